//! The SII EEPROM and its interface registers 0x0500–0x050F (esc-spec §5.3).
use ferrocat_wire::register::SiiControl;

/// Time an EEPROM read of one block keeps the interface busy, as real ESCs showed ethercrab
/// (Linux captures with per-frame timestamps, replay-*): of its 3 062 status polls, the busy
/// bit agrees with this time in 99.4 % (any time in 610–790 µs: ≥ 99.1 %; 20 µs: 34.8 %). The
/// datasheet's figures are not in our sources.
pub const READ_BUSY_NS: u64 = 700_000;
/// A word write (EEPROM page program) takes milliseconds.
pub const WRITE_BUSY_NS: u64 = 3_000_000;
pub const RELOAD_BUSY_NS: u64 = 100_000;

#[derive(Debug, Clone)]
pub struct Eeprom {
    pub data: Vec<u8>,
    pub busy_until_ns: u64,
    /// Error bits (ack/command error, write error) of 0x0502.
    pub errors: u16,
    /// Set when a reload was commanded; the ESC takes the configuration words again once the
    /// interface is no longer busy.
    pub reloaded: bool,
    /// 0x0502 bits 11 (checksum error) and 12 (configuration not loaded) from the last load of
    /// the ESC configuration area; unlike `errors`, a command does not clear them.
    pub load_status: u16,
}

/// Word 7 with this value switches the ESC configuration area's checksum test off, for
/// debugging (Beckhoff, EtherCAT Slave Controller Technology, Section I, Table 37, note; our
/// copy of it breaks off after "0x8", docs/esc-model.md).
pub const CHECKSUM_BYPASS: u16 = 0x88A4;

impl Eeprom {
    pub fn new(mut data: Vec<u8>) -> Self {
        // An EEPROM is at least the 128-byte header; missing words read as erased (0xFFFF).
        if data.len() < 128 {
            data.resize(128, 0xFF);
        }
        Eeprom { data, busy_until_ns: 0, errors: 0, reloaded: false, load_status: 0 }
    }

    pub fn word(&self, w: usize) -> u16 {
        match self.data.get(2 * w..2 * w + 2) {
            Some(b) => u16::from_le_bytes([b[0], b[1]]),
            None => 0xFFFF,
        }
    }

    /// Whether the ESC configuration area (words 0–6) matches its checksum, the low byte of
    /// word 7 (esc-spec §5.4), or word 7 switches the test off.
    pub fn config_area_ok(&self) -> bool {
        let check = self.word(7);
        check == CHECKSUM_BYPASS || check & 0xFF == ferrocat_wire::sii::header_crc(&self.data[..14]) as u16
    }

    pub fn busy(&self, now_ns: u64) -> bool {
        now_ns < self.busy_until_ns
    }

    /// Executes a command written to 0x0502 (with the address at 0x0504 and, for writes, the
    /// data at 0x0508). Returns the bytes to place at 0x0508 for a read.
    pub fn command(
        &mut self,
        now_ns: u64,
        control: u16,
        word_addr: u32,
        write_data: u16,
        read_8: bool,
    ) -> Option<[u8; 8]> {
        if self.busy(now_ns) {
            // A command while busy is refused (ack/command error).
            self.errors |= SiiControl::ACK_ERROR;
            return None;
        }
        match control & SiiControl::CMD_MASK {
            0 => {
                self.errors = 0;
                None
            }
            SiiControl::CMD_READ => {
                self.errors = 0;
                self.busy_until_ns = now_ns + READ_BUSY_NS;
                let mut out = [0u8; 8];
                let n = if read_8 { 4 } else { 2 };
                for i in 0..n {
                    out[2 * i..2 * i + 2].copy_from_slice(&self.word(word_addr as usize + i).to_le_bytes());
                }
                Some(out)
            }
            SiiControl::CMD_WRITE => {
                if control & SiiControl::WRITE_ENABLE == 0 {
                    self.errors = SiiControl::WRITE_ERROR;
                    return None;
                }
                self.errors = 0;
                let at = 2 * word_addr as usize;
                if at + 2 > self.data.len() {
                    self.errors = SiiControl::ACK_ERROR;
                    return None;
                }
                self.data[at..at + 2].copy_from_slice(&write_data.to_le_bytes());
                self.busy_until_ns = now_ns + WRITE_BUSY_NS;
                None
            }
            // The datasheet's reload is 0x0400; SOEM sends 0x0300 (esc-spec §5.3 [C]): accept both.
            SiiControl::CMD_RELOAD | 0x0300 => {
                self.errors = 0;
                self.busy_until_ns = now_ns + RELOAD_BUSY_NS;
                self.reloaded = true;
                None
            }
            _ => {
                self.errors = SiiControl::ACK_ERROR;
                None
            }
        }
    }
}
