//! Which registers an EtherCAT master may write (everything else is read-only from the ECAT
//! side and ignores writes), after the ET1100 register description.
use ferrocat_wire::register::addr;

/// Whether a byte at `a` is writable from the EtherCAT side (table lookup).
#[inline]
pub(crate) fn ecat_writable(a: u16) -> bool {
    a < 0x1000 && WRITABLE[(a >> 6) as usize] & (1 << (a & 63)) != 0
}

/// One bit per register byte, built at compile time from the rules below.
static WRITABLE: [u64; 64] = {
    let mut t = [0u64; 64];
    let mut a = 0u16;
    while a < 0x1000 {
        if writable_rule(a) {
            t[(a >> 6) as usize] |= 1 << (a & 63);
        }
        a += 1;
    }
    t
};

const fn writable_rule(a: u16) -> bool {
    matches!(a,
        0x0010..=0x0011            // station address
        | 0x0020..=0x0021 | 0x0030..=0x0031 // write enable/protection
        | 0x0040                   // ECAT reset
        | 0x0100..=0x0103          // DL control
        | 0x0108..=0x0109          // physical R/W offset
        | 0x0120..=0x0121          // AL control
        | 0x0200..=0x0201          // ECAT event mask
        | 0x0300..=0x0313          // error counters (a write clears)
        | 0x0400..=0x0401 | 0x0410..=0x0411 | 0x0420..=0x0421 // watchdogs
        | 0x0442..=0x0443          // watchdog counters (a write clears both)
        | 0x0500 | 0x0502..=0x050F // SII interface (0x0501 is PDI's)
        | 0x0510..=0x0515 | 0x0516 // MII management
        | 0x0600..=0x06FF          // FMMUs
        | 0x0900..=0x0903          // receive time port 0: a write latches (ports 1–3 r/-)
        | 0x0910..=0x0917          // system time (write feeds the time control loop)
        | 0x0920..=0x092B          // offset, delay
        | 0x0930..=0x0931 | 0x0934..=0x0936
        | 0x0980..=0x0981          // cyclic unit control, activation (pulse length: SII only)
        | 0x0990..=0x0997 | 0x09A0..=0x09A7 // start time, cycle times
        | 0x09A8..=0x09A9          // latch control
        | 0x0F80..=0x0FFF          // user RAM
    ) || sm_writable(a)
}

/// SyncManager registers: start, length, control and activate are ECAT-writable; status and
/// PDI control are not.
const fn sm_writable(a: u16) -> bool {
    if a < addr::SM0 || a >= addr::SM0 + 16 * 8 {
        return false;
    }
    matches!((a - addr::SM0) % 8, 0..=4 | 6)
}
