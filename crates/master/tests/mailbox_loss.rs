//! Mailbox exchanges through a segment that loses frames anywhere along it: a read lost after
//! the slave handed its message over is asked for again (the mailbox repeat), and a request
//! written again after its frame was lost on the way back is taken once.
use ferrocat_master::Master;
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};

const DRIVE: u16 = 1;

fn master(seed: u64, loss: f64) -> Master<VirtualIo> {
    let toml = format!(
        "seed = {seed}\nloss_probability = {loss}\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'SERVO'\n"
    );
    let cfg: SegmentConfig = toml::from_str(&toml).unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), seed));
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    m
}

#[test]
fn sdo_and_foe_transfers_come_through_five_percent_frame_loss() {
    let (mut repeats, mut duplicates) = (0, 0);
    let file: Vec<u8> = (0..3000u32).map(|k| (k * 7 + k / 251) as u8).collect();
    for seed in 1..=4 {
        let mut m = master(seed, 0.05);
        for k in 0..150u32 {
            // Expedited both ways, and a segmented upload (the device name, 0x1008).
            m.acyclic().coe().sdo_write(DRIVE, 0x607A, 0, &(k as i32).to_le_bytes()).unwrap();
            assert_eq!(
                m.acyclic().coe().sdo_read(DRIVE, 0x607A, 0).unwrap(),
                (k as i32).to_le_bytes(),
                "seed {seed}, {k}"
            );
            assert_eq!(m.acyclic().coe().sdo_read(DRIVE, 0x1018, 1).unwrap().len(), 4);
        }
        let name = m.acyclic().coe().sdo_read(DRIVE, 0x1008, 0).unwrap();
        assert!(!name.is_empty());
        m.acyclic().foe().write(DRIVE, "f.bin", 0, &file).unwrap();
        assert_eq!(m.acyclic().foe().read(DRIVE, "f.bin", 0, 1 << 20).unwrap(), file, "seed {seed}");
        repeats += m.slaves().at(DRIVE).unwrap().status().mailbox_repeats();
        duplicates += m.io().seg.nodes[DRIVE as usize].esc.mbx_duplicates;
        // Through INIT and configured again (SM1's activate written with the repeat bit
        // clear, whatever the last repeat left): the firmware takes that as its start, not as
        // a repeat request, and no old reply comes back.
        m.states().request_state_all(ferrocat_wire::register::AlState::Init).unwrap();
        m.states().configure().unwrap();
        for k in 0..20i32 {
            m.acyclic().coe().sdo_write(DRIVE, 0x607A, 0, &(-k).to_le_bytes()).unwrap();
            assert_eq!(
                m.acyclic().coe().sdo_read(DRIVE, 0x607A, 0).unwrap(),
                (-k).to_le_bytes(),
                "seed {seed} after INIT, {k}"
            );
        }
        // Every repeat the firmware made was one the master asked for.
        let answered = m.io().seg.nodes[DRIVE as usize].esc.mbx_repeats;
        assert_eq!(
            answered,
            m.slaves().at(DRIVE).unwrap().status().mailbox_repeats(),
            "seed {seed}: repeats answered and asked for"
        );
    }
    println!("mailbox repeats {repeats}, requests written twice and dropped {duplicates}");
    // Both paths ran: without them a lost read times out and a doubled request answers twice.
    assert!(repeats > 0 && duplicates > 0, "repeats {repeats}, duplicates {duplicates}");
}
