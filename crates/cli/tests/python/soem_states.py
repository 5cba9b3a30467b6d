"""Bringing a mapped SOEM master to OP as SOEM's simple_test does: SAFEOP, then OP requested
while process data runs (slaves with an SM watchdog want outputs before OP)."""
import pysoem

# Errors acknowledged on the way at most: a host that stalls the script for longer than a
# slave's process-data watchdog (100 ms; tests run side by side) takes that slave back to
# SAFEOP+ERROR (0x001B), which simple_test's supervision acknowledges before asking for OP
# again. A slave that refuses OP every time stays refused.
MAX_ACKS = 3


def to_op(m, exchange, tries=200, log=None):
    """`exchange()` sends and receives one cycle's process data. Whether every slave is in OP.
    Each acknowledged error goes to `log` as (slave index, AL status code)."""
    m.state = pysoem.SAFEOP_STATE
    m.write_state()
    m.state_check(pysoem.SAFEOP_STATE, 500_000)
    m.state = pysoem.OP_STATE
    m.write_state()
    acks = 0
    for _ in range(tries):
        exchange()
        if m.state_check(pysoem.OP_STATE, 1000) == pysoem.OP_STATE:
            return True
        # simple_test's supervision: acknowledge an error, then ask a slave in SAFEOP for OP.
        m.read_state()
        for i, s in enumerate(m.slaves):
            if s.state == pysoem.SAFEOP_STATE + pysoem.STATE_ERROR and acks < MAX_ACKS:
                acks += 1
                if log is not None:
                    log.append((i, s.al_status))
                s.state = pysoem.SAFEOP_STATE + pysoem.STATE_ACK
                s.write_state()
            elif s.state == pysoem.SAFEOP_STATE:
                s.state = pysoem.OP_STATE
                s.write_state()
    return False
