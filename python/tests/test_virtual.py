"""The master against the virtual segment in virtual time: scan, states, SDO, SII, the image
by name, DC lock, faults, determinism, errors, and that the GIL is released."""
import os
import threading
import time

import pytest

import ferrocat

LINE = ["EK1100", "EL2004", "EL1004", "SERVO"]


def virtual(devices=LINE, seed=1, **kw):
    return ferrocat.Master.virtual(ferrocat.Segment(devices, seed=seed), **kw)


def test_scan_finds_the_segment_s_devices_with_their_identities():
    m = virtual()
    slaves = m.scan()
    assert [s.position for s in slaves] == [0, 1, 2, 3]
    assert [s.state for s in slaves] == ["init"] * 4
    ek, el2004, el1004, servo = slaves
    # The identities the devices' EEPROMs carry (Beckhoff's vendor ID 2 and product codes).
    assert (ek.vendor_id, ek.product_code) == (2, 0x044C2C52)
    assert (el2004.vendor_id, el2004.product_code) == (2, 0x07D43052)
    assert (el1004.vendor_id, el1004.product_code) == (2, 0x03EC3052)
    assert servo.product_code == 0x402 and servo.has_coe and servo.dc
    assert not ek.has_coe
    assert len({s.station_address for s in slaves}) == 4


def test_bring_up_reaches_op_and_cycles_with_whole_working_counters():
    m = virtual()
    slaves = m.bring_up(cycle_us=1000)
    assert [s.state for s in slaves] == ["op"] * 4
    assert m.run(200) == 0, "every cycle's working counter whole"
    st = m.stats()
    assert st["cycles"] >= 200 and st["wkc_errors"] == 0 and st["lost_frames"] == 0
    assert st["last_wkc"] == m.expected_wkc
    # 200 cycles of 1 ms on the segment's clock.
    assert m.segment.stats()["time_s"] > 0.2
    for node in range(4):
        assert m.segment.device_state(node) == "op"


def test_entries_are_read_and_written_by_name_and_by_index():
    m = virtual()
    m.bring_up()
    names = [(v.position, v.name, v.direction) for v in m.variables()]
    assert (3, "Statusword", "input") in names and (3, "Controlword", "output") in names
    # The EL2004's four channels share the entry name "Output": the index tells them apart.
    outs = [v for v in m.variables() if v.position == 1]
    assert [v.index for v in outs] == [0x7000, 0x7010, 0x7020, 0x7030]
    m.set(1, "0x7010:01", 1)
    m.run(2)
    assert m.get(1, "0x7010:01") == 1 and m.get(1, "0x7000:01") == 0
    image = m.image()
    out_bytes, in_bytes = m.image_sizes
    assert len(image) == out_bytes + in_bytes
    bit = outs[1].bit_offset
    assert image[bit // 8] >> (bit % 8) & 1 == 1
    assert memoryview(image).nbytes == len(image)


def test_values_are_checked_against_the_entry_s_width():
    m = virtual()
    m.bring_up()
    with pytest.raises(ferrocat.Error, match="does not fit"):
        m.set(1, "0x7000:01", 2)
    m.set(3, "Target position", -5)
    m.run(1)
    assert m.get(3, "Target position", signed=True) == -5
    assert m.get(3, "Target position") == (1 << 32) - 5
    with pytest.raises(ferrocat.Error, match="Nonexistent"):
        m.get(3, "Nonexistent")


def test_sdo_read_write_and_information():
    m = virtual()
    m.bring_up()
    servo = m.slaves[3]
    vendor = m.sdo_read(3, 0x1018, 1)
    assert int.from_bytes(vendor, "little") == servo.vendor_id
    product = m.sdo_read(3, 0x1018, 2)
    assert int.from_bytes(product, "little") == servo.product_code
    assert 0x1018 in m.od_list(3)
    info = m.object_info(3, 0x1018)
    assert info["index"] == 0x1018 and info["max_subindex"] >= 4 and info["name"]
    entry = m.entry_info(3, 0x1018, 1)
    assert entry["bits"] == 32
    # Profile acceleration: written, read back.
    m.sdo_write(3, 0x6083, 0, (12345).to_bytes(4, "little"))
    assert int.from_bytes(m.sdo_read(3, 0x6083, 0), "little") == 12345


def test_an_sdo_abort_is_an_exception_with_its_code():
    m = virtual()
    m.bring_up()
    with pytest.raises(ferrocat.SdoAbort) as e:
        m.sdo_read(3, 0x5FFF, 0)
    # CiA 301: object does not exist in the object dictionary.
    assert e.value.code == 0x06020000
    assert (e.value.position, e.value.index, e.value.subindex) == (3, 0x5FFF, 0)
    assert "0x5fff" in str(e.value)
    assert isinstance(e.value, ferrocat.Error)


def test_sdo_wants_a_mailbox_which_configure_sets_up():
    m = virtual()
    m.scan()
    with pytest.raises(ferrocat.Error, match="INIT, where it has no mailbox"):
        m.sdo_read(3, 0x1018, 1)
    assert [s.state for s in m.configure()] == ["preop"] * 4
    assert int.from_bytes(m.sdo_read(3, 0x1018, 1), "little") == m.slaves[3].vendor_id


def test_sii_is_the_device_s_eeprom():
    m = virtual()
    m.scan()
    sii = m.sii_read(1)
    # ETG.2010: vendor ID at word 8, product code at word 10.
    assert int.from_bytes(sii[16:20], "little") == 2
    assert int.from_bytes(sii[20:24], "little") == 0x07D43052


def test_dc_locks_and_the_true_offset_is_small():
    m = virtual(["EK1100", "SERVO", "SERVO"])
    m.bring_up(cycle_us=1000)
    assert m.segment.true_offset_ns() is None and m.clock_sync() is None, "no DC yet"
    m = virtual(["EK1100", "SERVO", "SERVO"])
    m.bring_up(cycle_us=1000, dc=True, sync="ferrocat")
    m.run(1000)
    cs = m.clock_sync()
    assert cs["method"] == "ferrocat" and cs["lock"] == "locked"
    assert abs(cs["offset_ns"]) < 1000
    # What only the simulator knows: the master's clock against the reference's true time.
    assert abs(m.segment.true_offset_ns()) < 1000
    assert m.run(100) == 0
    assert [m.segment.device_state(n) for n in range(3)] == ["op"] * 3


def test_every_clock_sync_preset_is_taken_and_a_wrong_one_is_named():
    m = virtual(["EK1100", "SERVO"])
    with pytest.raises(ferrocat.Error, match="not a method"):
        m.bring_up(dc=True, sync="nonsense")
    m = virtual(["EK1100", "SERVO"])
    m.bring_up(dc=True, sync="conventional")
    m.run(50)
    assert m.clock_sync()["method"] == "conventional"


def test_the_same_seed_gives_the_same_run():
    def one(seed):
        m = virtual(["EK1100", "SERVO"], seed=seed)
        m.bring_up(dc=True)
        m.segment.loss_probability = 0.02
        m.run(500)
        return m.stats(), m.clock_sync(), m.segment.true_offset_ns(), m.image(), m.now_ns

    a, b = one(7), one(7)
    assert a == b
    assert one(8)[0:3] != a[0:3] or one(8)[4] != a[4]


def test_frames_lost_and_a_link_pulled_show_in_the_counters_and_events():
    m = virtual()
    m.bring_up()
    m.segment.loss_probability = 0.1
    short = m.run(300)
    assert short > 0 and m.stats()["lost_frames"] > 0
    assert m.segment.stats()["lost"] > 0
    m.segment.loss_probability = 0.0
    m.events()
    # The link between the EL2004 and the EL1004 pulled: the EL1004 and the servo are gone.
    m.segment.fault("link_down", node=2, port=0)
    assert m.run(50) == 50
    m.segment.fault("link_up", node=2, port=0)
    m.run(20)
    with pytest.raises(ferrocat.Error, match="unknown fault"):
        m.segment.fault("meteor", node=0)
    with pytest.raises(ferrocat.Error, match="no device 9"):
        m.segment.fault("power_off", node=9)


def test_a_drive_fault_is_seen_by_the_axis_which_resets_it_and_enables_again():
    m = virtual(["EK1100", "SERVO"])
    m.bring_up(csp=[1])
    ax = m.axis(1)
    ax.enable()
    m.segment.fault("drive_fault", node=1, code=0x2310)
    states = []
    for _ in range(30):
        m.cycle()
        states.append(ax.state)
    # Its goal is still operation enabled: the driver resets the fault and walks back.
    assert "Fault" in states
    assert states[-1] == "OperationEnabled" and ax.feedback()["ready"]


def test_errors_read_like_the_cli_s():
    with pytest.raises(ferrocat.Error, match="NOPE"):
        ferrocat.Segment(["NOPE"])
    with pytest.raises(ferrocat.Error, match="at least one device"):
        ferrocat.Segment([])
    with pytest.raises(ferrocat.Error, match="unknown host model"):
        virtual(host="toaster")
    m = virtual()
    with pytest.raises(ferrocat.Error, match="bring_up"):
        m.cycle()
    m.bring_up()
    with pytest.raises(ferrocat.Error, match="virtual segment"):
        m.start()
    with pytest.raises(ferrocat.Error, match="no slave 9|9"):
        m.sdo_read(9, 0x1000, 0)
    seg = ferrocat.Segment(["EK1100"])
    ferrocat.Master.virtual(seg)
    with pytest.raises(ferrocat.Error, match="in use"):
        ferrocat.Master.virtual(seg)


def test_the_gil_is_released_while_the_master_works():
    m = virtual()
    m.bring_up()
    ticks = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks.append(1)
            time.sleep(0)

    t = threading.Thread(target=count)
    t.start()
    before = len(ticks)
    m.run(3000)
    during = len(ticks) - before
    stop.set()
    t.join()
    assert during > 0, "a Python thread ran while the master ran 3000 cycles"


def test_state_requests_step_a_slave_and_come_back():
    m = virtual()
    m.bring_up()
    m.request_state("safeop", position=1)
    assert m.segment.device_state(1) == "safeop"
    m.request_state("op", position=1)
    assert m.segment.device_state(1) == "op"
    with pytest.raises(ferrocat.Error, match="state 'sleepy'"):
        m.request_state("sleepy")
    m.shut_down()
    assert [m.segment.device_state(n) for n in range(4)] == ["init"] * 4


def test_segments_from_a_machine_description_and_an_eni(tmp_path):
    desc = tmp_path / "bench.toml"
    desc.write_text(
        'name = "bench"\n'
        '[[slave]]\nname = "coupler"\nvendor = 2\nproduct = 0x044c2c52\ndevice = "EK1100"\n'
        '[[slave]]\nname = "axis"\nvendor = 0\nproduct = 0x402\ndevice = "SERVO"\n'
    )
    seg = ferrocat.Segment.from_machine(desc, seed=2)
    assert len(seg.devices) == 2
    m = ferrocat.Master.virtual(seg)
    assert [(s.vendor_id, s.product_code) for s in m.scan()] == [(2, 0x044C2C52), (0, 0x402)]
    (tmp_path / "empty.toml").write_text('name = "nothing"\n')
    with pytest.raises(ferrocat.Error, match="names no slave"):
        ferrocat.Segment.from_machine(tmp_path / "empty.toml")
    (tmp_path / "nodevice.toml").write_text('[[slave]]\nname = "x"\nvendor = 2\nproduct = 1\n')
    with pytest.raises(ferrocat.Error, match="no `device = …`"):
        ferrocat.Segment.from_machine(tmp_path / "nodevice.toml")
    eni = os.path.join(os.path.dirname(__file__), "../../crates/machine/tests/data/ferrocat_lenient.eni.xml")
    m = ferrocat.Master.virtual(ferrocat.Segment.from_eni(eni))
    assert len(m.scan()) >= 1


def test_an_al_error_takes_the_slave_to_safeop():
    m = virtual(["EK1100", "EL2004", "EL1004"])
    m.bring_up()
    assert m.segment.device_state(2) == "op"
    m.segment.fault("al_error", node=2, code=0x8001, at_s=0.005)
    states = []
    for _ in range(20):
        m.cycle()
        states.append(m.segment.device_state(2))
    assert states[0] == "op" and states[-1] == "safeop", states
    with pytest.raises(ferrocat.Error, match="al_error|unknown fault"):
        m.segment.fault("al_errors", node=2)
