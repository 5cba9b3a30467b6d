//! `ferrocat.Slave` and `ferrocat.Variable`: what the scan found, as plain Python values.
use pyo3::prelude::*;

/// A slave as the master found it at the scan.
#[pyclass(module = "ferrocat", frozen, get_all)]
#[derive(Clone)]
pub struct Slave {
    /// Position on the segment, from 0.
    pub position: u16,
    /// The name its EEPROM gives.
    pub name: String,
    pub vendor_id: u32,
    pub product_code: u32,
    pub revision: u32,
    pub serial: u32,
    /// The configured station address.
    pub station_address: u16,
    /// The alias from its EEPROM (0: none).
    pub alias: u16,
    /// Its AL state when last read (`init`, `preop`, `bootstrap`, `safeop`, `op`).
    pub state: String,
    /// It speaks CoE (SDO).
    pub has_coe: bool,
    /// Its DC unit has a system time that can be synchronised.
    pub dc: bool,
    /// Bits of outputs and of inputs mapped.
    pub output_bits: u32,
    pub input_bits: u32,
    /// Its mapped entries.
    pub outputs: Vec<Variable>,
    pub inputs: Vec<Variable>,
}

/// A process-data entry: where it sits in the image and what it is.
#[pyclass(module = "ferrocat", frozen, get_all)]
#[derive(Clone)]
pub struct Variable {
    /// The slave's position.
    pub position: u16,
    /// The entry's name (from CoE, the SII or the ESI).
    pub name: String,
    pub index: u16,
    pub subindex: u8,
    /// Its width in bits.
    pub bits: u8,
    /// Bit offset in the whole process image (outputs first, then inputs).
    pub bit_offset: u32,
    /// `output` or `input`.
    pub direction: &'static str,
}

impl Variable {
    fn of(position: u16, e: &ferrocat_master::Mapped, direction: &'static str) -> Self {
        Variable {
            position,
            name: e.name.clone(),
            index: e.index,
            subindex: e.subindex,
            bits: e.bits,
            bit_offset: e.image_bit,
            direction,
        }
    }
    pub fn all_of(s: &ferrocat_master::Slave) -> Vec<Variable> {
        let m = s.mapping();
        let out = m.outputs.iter().map(|e| Variable::of(s.position(), e, "output"));
        out.chain(m.inputs.iter().map(|e| Variable::of(s.position(), e, "input"))).collect()
    }
}

#[pymethods]
impl Variable {
    fn __repr__(&self) -> String {
        format!(
            "Variable(position={}, name='{}', {:#06x}:{:#04x}, {} bits, {})",
            self.position, self.name, self.index, self.subindex, self.bits, self.direction
        )
    }
}

impl From<&ferrocat_master::Slave> for Slave {
    fn from(s: &ferrocat_master::Slave) -> Self {
        let id = s.identity();
        let m = s.mapping();
        Slave {
            position: s.position(),
            name: s.name().to_string(),
            vendor_id: id.vendor_id,
            product_code: id.product_code,
            revision: id.revision,
            serial: id.serial,
            station_address: s.station(),
            alias: s.alias(),
            state: s.status().state().name().to_ascii_lowercase(),
            has_coe: s.mailbox().is_some_and(|mb| mb.has_coe()),
            dc: s.dc().has_system_time,
            output_bits: m.output_bits(),
            input_bits: m.input_bits(),
            outputs: m.outputs.iter().map(|e| Variable::of(s.position(), e, "output")).collect(),
            inputs: m.inputs.iter().map(|e| Variable::of(s.position(), e, "input")).collect(),
        }
    }
}

#[pymethods]
impl Slave {
    fn __repr__(&self) -> String {
        format!(
            "Slave({}, '{}', vendor {:#x}, product {:#x}, rev {:#x}, {})",
            self.position, self.name, self.vendor_id, self.product_code, self.revision, self.state
        )
    }
}
