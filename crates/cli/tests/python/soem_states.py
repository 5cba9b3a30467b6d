"""Bringing a mapped SOEM master to OP as SOEM's simple_test does: SAFEOP, then OP requested
while process data runs (slaves with an SM watchdog want outputs before OP)."""
import pysoem


def to_op(m, exchange, tries=200):
    """`exchange()` sends and receives one cycle's process data. Whether every slave is in OP."""
    m.state = pysoem.SAFEOP_STATE
    m.write_state()
    m.state_check(pysoem.SAFEOP_STATE, 500_000)
    m.state = pysoem.OP_STATE
    m.write_state()
    for _ in range(tries):
        exchange()
        if m.state_check(pysoem.OP_STATE, 1000) == pysoem.OP_STATE:
            return True
    return False
