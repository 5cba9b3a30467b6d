//! Decoding speed over real traffic: every EtherCAT frame of all shared captures (TwinCAT, SOEM
//! and ethercrab masters; APRD … FRMW, mailbox and process data), parsed and walked datagram by
//! datagram. Throughput is reported in datagrams per second.
use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use ferrocat_wire::Frame;

fn frames() -> Option<Vec<Vec<u8>>> {
    let dir = match ferrocat_testdata::try_shared_dir() {
        Ok(d) => d,
        Err(reason) => {
            eprintln!("decode benchmark skipped: {reason}");
            return None;
        }
    };
    let mut out = Vec::new();
    let mut files: Vec<_> = std::fs::read_dir(dir.join("captures")).ok()?.flatten().map(|e| e.path()).collect();
    files.sort();
    for path in files.into_iter().filter(|p| p.extension().is_some_and(|e| e == "pcapng")) {
        let bytes = std::fs::read(&path).ok()?;
        ferrocat_capture::for_each_packet(&bytes, |p| {
            if let Ok(Some(_)) = Frame::parse(&p.data) {
                out.push(p.data.to_vec());
            }
            Ok(())
        })
        .ok()?;
    }
    Some(out)
}

fn decode(c: &mut Criterion) {
    let Some(frames) = frames() else { return };
    let datagrams: usize = frames.iter().map(|f| Frame::parse(f).unwrap().unwrap().pdu.datagram_count()).sum();
    let mut g = c.benchmark_group("decode");
    g.throughput(Throughput::Elements(datagrams as u64));
    g.bench_function(format!("{} frames / {datagrams} datagrams of real captures", frames.len()), |b| {
        b.iter(|| {
            let mut acc = 0u64;
            for f in &frames {
                let frame = Frame::parse(black_box(f)).unwrap().unwrap();
                for d in frame.pdu.datagrams() {
                    acc = acc.wrapping_add(
                        d.wkc() as u64 + d.header().len as u64 + d.data().first().copied().unwrap_or(0) as u64,
                    );
                }
            }
            acc
        })
    });
    g.finish();
}

criterion_group!(benches, decode);
criterion_main!(benches);
