"""Sends frames a simulator must survive onto IFACE: an EtherCAT frame whose header length lies,
one whose datagram length lies, a frame that is not EtherCAT, and a runt."""
import socket
import sys

s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW)
s.bind((sys.argv[1], 0))
eth = b"\xff" * 6 + b"\x02\x00\x00\x00\x00\x09"
s.send(eth + b"\x88\xa4" + b"\xff\x17" + b"\x07\x00" + b"\x00" * 44)               # header length 2047
s.send(eth + b"\x88\xa4" + b"\x0e\x10" + b"\x07\x00\x00\x00\x00\x00\xff\x07" + b"\x00" * 38)  # datagram length 2047
s.send(eth + b"\x08\x06" + b"\x00" * 46)                                           # ARP-like, not EtherCAT
s.send(eth + b"\x88\xa4")                                                          # runt
print("sent 4")
