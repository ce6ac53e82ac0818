//! Round trip of interface kinematics between two processes on loopback, against a memcpy
//! of the same bytes (REFERENCE D, "Transport"). Prints figures; it is not a timed test.
//!
//! `cargo bench -p proto --bench transport` (set COSIM_BENCH_ROUNDS to change the count).
//! The echo side is this same executable, started again with COSIM_BENCH_ECHO set.

use std::time::{Duration, Instant};

use proto::link::free_loopback_port;
use proto::participant::Participant;
use proto::{
    Hello, InterfaceDecl, InterfaceForces, InterfaceKind, InterfaceKinematics, Label, LinkConfig,
    NodeKind, PROTOCOL_VERSION,
};

const RUN: &str = "bench-transport";

fn hello(kind: NodeKind) -> Hello {
    Hello {
        software: "transport-bench".into(),
        kind,
        capabilities: vec![],
        pid: std::process::id(),
    }
}

/// The echo process: the DEM side, answering each window's kinematics with forces of the
/// same size (the positions array, re-sent), like a coupling window's exchange.
async fn echo(listen: u16, connect: u16, sizes: &[usize], rounds: usize) {
    let mut dem = Participant::connect(
        &link(Some(listen), &[connect]),
        RUN,
        "dem",
        hello(NodeKind::Dem),
    )
    .await
    .expect("echo connects");
    let ifaces: Vec<String> = sizes.iter().map(|n| format!("n{n}")).collect();
    dem.open_interfaces(&decls(&ifaces)).await.expect("open");
    dem.wait_for_peers(Duration::from_secs(30))
        .await
        .expect("peer");
    for (&n, name) in sizes.iter().zip(&ifaces) {
        for k in 0..(rounds + 10) as u64 {
            let kin = dem
                .read_kinematics(name, Label::window(k), n, Duration::from_secs(60))
                .await
                .expect("kinematics");
            let f = InterfaceForces {
                version: PROTOCOL_VERSION,
                run_id: RUN.into(),
                interface: name.clone(),
                window: k,
                iteration: 0,
                time: kin.time,
                forces: kin.positions,
                averaged: false,
                samples: 1,
            };
            dem.write_forces(&f).await.expect("forces");
        }
    }
    dem.finish().await.ok();
}

/// The bench's interfaces, provided by `fem`, used by `dem`.
fn decls(names: &[String]) -> Vec<InterfaceDecl> {
    names
        .iter()
        .map(|name| InterfaceDecl {
            name: name.clone(),
            kind: InterfaceKind::Surface,
            provider: "fem".into(),
            users: vec!["dem".into()],
            force_averaging: false,
            relaxed_forces: false,
            relaxed_kinematics: false,
        })
        .collect()
}

/// A loopback peer; COSIM_BENCH_ZENOH_CONFIG names a zenoh config file to start from (e.g. one
/// that switches shared memory off, to measure the TCP path).
fn link(listen: Option<u16>, connect: &[u16]) -> LinkConfig {
    LinkConfig {
        zenoh_config: std::env::var_os("COSIM_BENCH_ZENOH_CONFIG").map(Into::into),
        ..LinkConfig::loopback_peer(listen, connect)
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

fn main() {
    // COSIM_BENCH_DEFAULT_MALLOC=1 measures without the nodes' allocator tuning
    if std::env::var_os("COSIM_BENCH_DEFAULT_MALLOC").is_none() {
        proto::alloc::keep_message_buffers();
    }
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("tokio runtime")
        .block_on(bench());
}

async fn bench() {
    let sizes: Vec<usize> = match std::env::var("COSIM_BENCH_SIZES") {
        Ok(s) => s
            .split(',')
            .map(|x| x.trim().parse().expect("COSIM_BENCH_SIZES: node counts"))
            .collect(),
        Err(_) => vec![1_000, 10_000, 100_000],
    };
    let rounds: usize = std::env::var("COSIM_BENCH_ROUNDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(200);
    if let Ok(ports) = std::env::var("COSIM_BENCH_ECHO") {
        let (l, c) = ports.split_once(',').expect("ports");
        echo(l.parse().unwrap(), c.parse().unwrap(), &sizes, rounds).await;
        return;
    }
    let (pf, pd) = (free_loopback_port().unwrap(), free_loopback_port().unwrap());
    let mut fem = Participant::connect(&link(Some(pf), &[]), RUN, "fem", hello(NodeKind::Fem))
        .await
        .unwrap();
    let ifaces: Vec<String> = sizes.iter().map(|n| format!("n{n}")).collect();
    fem.open_interfaces(&decls(&ifaces)).await.unwrap();
    let mut child = std::process::Command::new(std::env::current_exe().unwrap())
        .env("COSIM_BENCH_ECHO", format!("{pd},{pf}"))
        .spawn()
        .expect("spawn echo process");
    fem.wait_for_peers(Duration::from_secs(30)).await.unwrap();
    println!("interface kinematics round trip between two processes on loopback (zenoh peers, TCP), {rounds} rounds after 10 warm-up");
    println!(
        "{:>8} {:>10} {:>12} {:>12} {:>12} {:>12} {:>12} {:>12} {:>12}",
        "nodes",
        "bytes",
        "median_us",
        "p90_us",
        "MB/s",
        "memcpy_us",
        "encode_us",
        "decode_us",
        "check_us"
    );
    for (&n, name) in sizes.iter().zip(&ifaces) {
        let bytes = 72 * n; // P, V, A as f64
        let mut times = Vec::with_capacity(rounds);
        for k in 0..(rounds + 10) as u64 {
            let kin = InterfaceKinematics {
                version: PROTOCOL_VERSION,
                run_id: RUN.into(),
                interface: name.clone(),
                window: k,
                iteration: 0,
                time: k as f64,
                positions: vec![k as f64; 3 * n].into(),
                velocities: vec![1.0; 3 * n].into(),
                accelerations: vec![2.0; 3 * n].into(),
            };
            let t = Instant::now();
            fem.write_kinematics(&kin).await.unwrap();
            let f = fem
                .read_forces(name, Label::window(k), n, Duration::from_secs(60))
                .await
                .unwrap();
            let dt = t.elapsed().as_secs_f64();
            assert_eq!(f.forces.0[0], k as f64);
            if k >= 10 {
                times.push(dt * 1e6);
            }
        }
        let mut sorted = times.clone();
        let med = median(&mut sorted);
        let p90 = sorted[(sorted.len() * 9) / 10];
        // memcpy of the same bytes (the floor of any transport)
        let src = vec![1.0f64; 9 * n];
        let mut dst = vec![0.0f64; 9 * n];
        let mut mc = Vec::new();
        for _ in 0..50 {
            let t = Instant::now();
            dst.copy_from_slice(std::hint::black_box(&src));
            std::hint::black_box(&dst);
            mc.push(t.elapsed().as_secs_f64() * 1e6);
        }
        let mcm = median(&mut mc);
        // the codec's share: encode the kinematics and the forces, decode and validate both
        // (what the round trip does besides moving bytes)
        let kin = InterfaceKinematics {
            version: PROTOCOL_VERSION,
            run_id: RUN.into(),
            interface: name.clone(),
            window: 0,
            iteration: 0,
            time: 0.0,
            positions: vec![1.0; 3 * n].into(),
            velocities: vec![1.0; 3 * n].into(),
            accelerations: vec![2.0; 3 * n].into(),
        };
        let forces = InterfaceForces {
            version: PROTOCOL_VERSION,
            run_id: RUN.into(),
            interface: name.clone(),
            window: 0,
            iteration: 0,
            time: 0.0,
            forces: vec![1.0; 3 * n].into(),
            averaged: false,
            samples: 1,
        };
        let (mut enc, mut dec) = (Vec::new(), Vec::new());
        for _ in 0..50 {
            let t = Instant::now();
            let a = proto::encode(std::hint::black_box(&kin)).unwrap();
            let b = proto::encode(std::hint::black_box(&forces)).unwrap();
            enc.push(t.elapsed().as_secs_f64() * 1e6);
            let t = Instant::now();
            let k2: InterfaceKinematics = proto::decode(&a, RUN).unwrap();
            let f2: InterfaceForces = proto::decode(&b, RUN).unwrap();
            dec.push(t.elapsed().as_secs_f64() * 1e6);
            std::hint::black_box((k2, f2));
        }
        // the finiteness checks (sender and receiver each check every value)
        let mut chk = Vec::new();
        for _ in 0..50 {
            let t = Instant::now();
            for a in [
                &kin.positions,
                &kin.velocities,
                &kin.accelerations,
                &forces.forces,
            ] {
                assert!(std::hint::black_box(a).first_non_finite().is_none());
            }
            chk.push(t.elapsed().as_secs_f64() * 1e6);
        }
        let chkm = median(&mut chk);
        let (encm, decm) = (median(&mut enc), median(&mut dec));
        // bytes moved per round trip: kinematics out (72 B/node) + forces back (24 B/node)
        let mbps = (96 * n) as f64 / (med * 1e-6) / 1e6;
        println!("{n:>8} {bytes:>10} {med:>12.1} {p90:>12.1} {mbps:>12.1} {mcm:>12.1} {encm:>12.1} {decm:>12.1} {chkm:>12.1}");
    }
    let (n, shm) = fem.data_received();
    println!("forces received: {n}, of which in shared memory: {shm}");
    let _ = child.wait();
    fem.finish().await.ok();
}
