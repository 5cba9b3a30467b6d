"""The propagation delays SOEM writes to each slave's 0x0928, read off the wire.

pysoem does not expose SOEM's computed delays, and a terminal whose ET1200 has receive times
only (its SYNC and latch units off, as on the real EL2004/EL1004) does not take the write: the
FPWR comes back with WKC 0 and the register cannot be read. The datagram still carries the value
SOEM computed — the real captures show the same write with WKC 0 — so a raw socket on the test's
own interface records it.
"""
import socket
import struct

ETH_P_ALL = 0x0003
ETHERCAT = 0x88A4
FPWR = 0x05


class DelayWrites:
    """Records FPWR datagrams to 0x0928 on `iface` from now until `stop`: {station: delay_ns}.

    No thread: pysoem keeps the interpreter while SOEM runs, so the kernel queues the frames on
    the socket and `stop` reads them all.
    """

    def __init__(self, iface):
        self.sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.sock.bind((iface, 0))
        self.delays = {}

    def _parse(self, frame):
        if len(frame) < 16 or struct.unpack(">H", frame[12:14])[0] != ETHERCAT:
            return
        (header,) = struct.unpack("<H", frame[14:16])
        end = min(len(frame), 16 + (header & 0x07FF))
        off = 16
        while off + 12 <= end:
            cmd, _idx, adp, ado, lf, _irq = struct.unpack("<BBHHHH", frame[off : off + 10])
            n = lf & 0x07FF
            if off + 12 + n > end:
                return
            if cmd == FPWR and ado == 0x0928 and n == 4:
                self.delays[adp] = struct.unpack("<I", frame[off + 10 : off + 14])[0]
            off += 12 + n
            if not lf & 0x8000:
                return

    def stop(self):
        self.sock.setblocking(False)
        while True:
            try:
                self._parse(self.sock.recv(2048))
            except BlockingIOError:
                break
        self.sock.close()
        return self.delays


def soem_delay(slave, station, written):
    """SOEM's delay for `slave`: as written on the wire, else (the reference, which SOEM does
    not write) as its 0x0928 reads; None if neither."""
    import pysoem

    if station in written:
        return written[station]
    try:
        return struct.unpack("<I", slave._fprd(0x0928, 4))[0]
    except pysoem.WkcError:
        return None
