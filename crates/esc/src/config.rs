//! What kind of ESC is simulated: identification and feature registers, memory sizes, DC width.
use ferrocat_wire::register::Features;

/// Width of the DC system time (esc-spec §3.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DcWidth {
    /// No DC unit: the DC registers read as absent (WKC 0).
    None,
    /// 32-bit system time (ESC20-like), wrapping every ≈4.29 s.
    Bits32,
    Bits64,
}

/// Which frame the receive-time latches of ports 1–3 take after a write to 0x0900 (esc-spec
/// 0x0900, 0x0936). Port 0 and 0x0918 always take the frame that carries the write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReceiveLatch {
    /// Every port the frame that carries the write, also one that passed before the
    /// processing unit saw it (ET1100; assumed for the LAN9252, whose datasheet does not say).
    ThisFrame,
    /// The write latches port 0 and enables ports 1–3, each of which then takes the first
    /// frame it receives and is disabled (ET1200, ESC20; register description, 0x0904).
    NextFrame,
    /// The IP core: 0x0936 = 0 forwarding mode (as `NextFrame`), 1 reverse mode (ports 1–3
    /// take the last frame each received before the write).
    Selectable,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EscConfig {
    pub esc_type: u8,
    pub revision: u8,
    pub build: u16,
    pub fmmu_count: u8,
    pub sm_count: u8,
    pub ram_kb: u8,
    /// 0x0007: two bits per port (00 none, 01 not configured, 10 E-Bus, 11 MII).
    pub port_descriptor: u8,
    pub features: u16,
    pub dc: DcWidth,
    /// SII interface reads 8 bytes (bit 6 of 0x0502) rather than 4.
    pub sii_read_8: bool,
    /// PDI control and ESC configuration (0x0140–0x0141) fixed at synthesis (an IP core), not
    /// loaded from SII word 0.
    pub pdi_control: Option<u16>,
    /// The PDI emulates the EEPROM (0x0502 bit 5).
    pub eeprom_emulation: bool,
    pub receive_latch: ReceiveLatch,
}

impl EscConfig {
    /// Beckhoff ET1100: 4 ports, 8 FMMUs, 8 SMs, 8 KiB, 64-bit DC. Type, build and features
    /// as real EK1100 couplers report them (0x0000 reads in the shared captures: type 0x11,
    /// build 3, features 0x00FC).
    pub fn et1100() -> Self {
        EscConfig {
            esc_type: 0x11,
            revision: 0x00,
            build: 0x0003,
            fmmu_count: 8,
            sm_count: 8,
            ram_kb: 8,
            port_descriptor: 0b10_10_10_11,
            features: 0x00FC,
            dc: DcWidth::Bits64,
            sii_read_8: true,
            pdi_control: None,
            eeprom_emulation: false,
            receive_latch: ReceiveLatch::ThisFrame,
        }
    }

    /// Beckhoff ET1200, the ESC of E-Bus terminals: 3 FMMUs, 4 SMs, 1 KiB. Type and features as
    /// real EL terminals report them in the shared captures: features 0x01FC, a 64-bit DC
    /// (bit 3) and enhanced DC SYNC activation (bit 8), read from the EL2828, EL1004 and EL3004
    /// (`replay-dc.pcapng` frame 364, `soem-sdinfo-ek1100-el1004.pcapng` frame 199,
    /// `twincat-scan-boxes.pcapng` frame 545); a BRD of 0x0000 over ET1100 + ET1200 reads 0x13.
    pub fn et1200() -> Self {
        EscConfig {
            esc_type: 0x12,
            revision: 0x00,
            build: 0x0001,
            fmmu_count: 3,
            sm_count: 4,
            ram_kb: 1,
            port_descriptor: 0b00_00_10_10,
            features: 0x01FC,
            dc: DcWidth::Bits64,
            sii_read_8: true,
            pdi_control: None,
            eeprom_emulation: false,
            receive_latch: ReceiveLatch::NextFrame,
        }
    }

    /// Microchip LAN9252: 2 MII ports, 3 FMMUs, 4 SMs, 4 KiB, 64-bit DC (esc-spec §7). Type,
    /// revision, port descriptor and features as a real one answered SOEM
    /// (soem-single-lan9252: 0x0000 = 0xC0, 0x02; 0x0007 = 0x1F; 0x0008 = 0x01CC).
    pub fn lan9252() -> Self {
        EscConfig {
            esc_type: 0xC0,
            revision: 0x02,
            build: 0x0001,
            fmmu_count: 3,
            sm_count: 4,
            ram_kb: 4,
            // Ports 0 and 1 MII; port 2 (a third port through an external PHY) "not
            // configured" (01), as the real one reads 0x0007 = 0x1F.
            port_descriptor: 0b00_01_11_11,
            features: Features::DC
                | Features::DC_64BIT
                | Features::MII_ENHANCED_LINK_DETECTION
                | Features::SEPARATE_FCS_ERRORS
                | Features::ENHANCED_DC_SYNC_ACTIVATION,
            dc: DcWidth::Bits64,
            sii_read_8: false,
            pdi_control: None,
            eeprom_emulation: false,
            receive_latch: ReceiveLatch::ThisFrame,
        }
    }

    /// An ESC20-like controller with a 32-bit DC.
    pub fn esc20() -> Self {
        EscConfig {
            esc_type: 0x02,
            revision: 0x02,
            build: 0x0001,
            fmmu_count: 4,
            sm_count: 4,
            ram_kb: 4,
            port_descriptor: 0b00_00_11_11,
            features: Features::DC,
            dc: DcWidth::Bits32,
            sii_read_8: false,
            pdi_control: None,
            eeprom_emulation: false,
            receive_latch: ReceiveLatch::NextFrame,
        }
    }

    /// Beckhoff's EtherCAT IP core in an FPGA as the Kollmorgen AKD drive carries it, from its
    /// captures: 0x0000–0x0009 = 04 02 43 00 03 04 04 0F 84 01 (type 0x04, revision 2, build
    /// 0x43, 3 FMMUs, 4 SMs, 4 KiB, two MII ports, features 0x0184: a 32-bit DC — its system
    /// time and 0x0918 read 0 in their upper half, and TwinCAT distributes it with a 4-byte
    /// ARMW); PDI control 0x0C08 set at synthesis (its SII word 0 says 0x0009); the EEPROM
    /// emulated by the PDI (0x0502 reads 0x0020: bit 5, 4-byte reads).
    pub fn ipcore() -> Self {
        EscConfig {
            esc_type: 0x04,
            revision: 0x02,
            build: 0x0043,
            fmmu_count: 3,
            sm_count: 4,
            ram_kb: 4,
            port_descriptor: 0b00_00_11_11,
            features: Features::DC | Features::SEPARATE_FCS_ERRORS | Features::ENHANCED_DC_SYNC_ACTIVATION,
            dc: DcWidth::Bits32,
            sii_read_8: false,
            pdi_control: Some(0x0C08),
            eeprom_emulation: true,
            receive_latch: ReceiveLatch::Selectable,
        }
    }

    /// An ESC without a DC unit (EK1100 couplers have one; some simple devices do not).
    pub fn without_dc(mut self) -> Self {
        self.features &= !(Features::DC | Features::DC_64BIT);
        self.dc = DcWidth::None;
        self
    }

    /// Bytes of the whole address space: registers, user RAM and process RAM.
    pub fn memory_len(&self) -> usize {
        0x1000 + self.ram_kb as usize * 1024
    }

    /// Whether port `n` can carry a link.
    pub fn has_port(&self, n: u8) -> bool {
        ferrocat_wire::register::PortDescriptor(self.port_descriptor).can_link(n)
    }
}
