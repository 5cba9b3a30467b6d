//! The virtual segment of `ferrocat-segment`, served in real time: on a network interface
//! through an AF_PACKET socket, io_uring or a packet ring, or as EtherCAT over UDP, with
//! CLOCK_MONOTONIC mapped onto the segment's true time ([`serve`]); and the virtual-time
//! workload its speed benchmarks measure ([`mod@bench`]). The segment's own crate stays
//! deterministic and compiles no socket.
pub mod bench;
pub mod serve;
