//! Two participants on loopback over real zenoh sessions.

use std::time::{Duration, Instant};

use proto::link::free_loopback_port;
use proto::participant::Participant;
use proto::{
    Hello, InterfaceDecl, InterfaceKind, InterfaceKinematics, Label, LinkConfig, NodeKind,
    ProtoError, PROTOCOL_VERSION,
};

fn hello(kind: NodeKind) -> Hello {
    Hello {
        software: "link-test".into(),
        kind,
        capabilities: vec![],
        pid: std::process::id(),
    }
}

fn kinematics(run: &str, window: u64, nodes: usize) -> InterfaceKinematics {
    let w = window as f64;
    InterfaceKinematics {
        version: PROTOCOL_VERSION,
        run_id: run.into(),
        interface: "top".into(),
        window,
        iteration: 0,
        time: w * 1e-4,
        positions: (0..3 * nodes)
            .map(|i| w + i as f64 * 1e-6)
            .collect::<Vec<_>>()
            .into(),
        velocities: vec![w; 3 * nodes].into(),
        accelerations: vec![-w; 3 * nodes].into(),
    }
}

/// Interface `top`, provided by `fem`, used by `dem`.
fn top() -> Vec<InterfaceDecl> {
    vec![InterfaceDecl {
        name: "top".into(),
        kind: InterfaceKind::Surface,
        provider: "fem".into(),
        users: vec!["dem".into()],
        force_averaging: false,
        relaxed_forces: false,
        relaxed_kinematics: false,
    }]
}

/// A FEM and a DEM participant on loopback with interface `top` open and matched.
async fn coupled_pair(run: &str) -> (Participant, Participant) {
    coupled_pair_with(run, None).await
}

/// The same, both sessions opened from zenoh configuration file `zenoh_config` if given.
async fn coupled_pair_with(
    run: &str,
    zenoh_config: Option<&std::path::Path>,
) -> (Participant, Participant) {
    let (pf, pd) = (free_loopback_port().unwrap(), free_loopback_port().unwrap());
    let ifaces = top();
    let link = |listen, connect: &[u16]| LinkConfig {
        zenoh_config: zenoh_config.map(Into::into),
        ..LinkConfig::loopback_peer(Some(listen), connect)
    };
    let fem_link = link(pf, &[]);
    let mut fem = Participant::connect(&fem_link, run, "fem", hello(NodeKind::Fem))
        .await
        .unwrap();
    let dem_link = link(pd, &[pf]);
    let mut dem = Participant::connect(&dem_link, run, "dem", hello(NodeKind::Dem))
        .await
        .unwrap();
    fem.open_interfaces(&ifaces).await.unwrap();
    dem.open_interfaces(&ifaces).await.unwrap();
    fem.wait_for_peers(Duration::from_secs(10)).await.unwrap();
    dem.wait_for_peers(Duration::from_secs(10)).await.unwrap();
    (fem, dem)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn thousand_windows_of_10k_node_kinematics_arrive_in_order_none_lost_none_duplicated() {
    const WINDOWS: u64 = 1000;
    const NODES: usize = 10_000;
    let run = "link-order";
    let (fem, mut dem) = coupled_pair(run).await;

    let t0 = Instant::now();
    let sender = tokio::spawn(async move {
        for k in 0..WINDOWS {
            fem.write_kinematics(&kinematics(run, k, NODES))
                .await
                .unwrap();
        }
        fem
    });
    for k in 0..WINDOWS {
        // read_kinematics refuses any other window index: a lost or duplicated message fails here
        let got = dem
            .read_kinematics("top", Label::window(k), NODES, Duration::from_secs(20))
            .await
            .unwrap();
        assert_eq!(got, kinematics(run, k, NODES), "window {k}");
    }
    let fem = sender.await.unwrap();
    let secs = t0.elapsed().as_secs_f64();
    eprintln!(
        "{WINDOWS} windows × {NODES} nodes in {secs:.2} s: {:.0} MB/s",
        WINDOWS as f64 * (NODES * 72) as f64 / secs / 1e6
    );
    // nothing more is queued: no duplicate arrived after the last window
    let extra = dem
        .read_kinematics(
            "top",
            Label::window(WINDOWS),
            NODES,
            Duration::from_millis(300),
        )
        .await;
    assert!(
        matches!(extra, Err(ProtoError::Timeout { .. })),
        "{extra:?}"
    );
    fem.finish().await.unwrap();
    dem.finish().await.unwrap();
}

/// On one host, interface data travel in shared memory (encoded straight into zenoh's pool);
/// with shared memory switched off in the zenoh configuration (as between machines) the same
/// calls send them over the link. Both arrive intact, with small messages always over the link.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn interface_data_use_shared_memory_on_one_host_and_the_link_without_it() {
    let dir = tempfile::tempdir().unwrap();
    let off = dir.path().join("no-shm.json5");
    std::fs::write(&off, "{ transport: { shared_memory: { enabled: false } } }").unwrap();
    for (zenoh_config, expect_shm) in [(None, true), (Some(off.as_path()), false)] {
        let run = if expect_shm { "link-shm" } else { "link-noshm" };
        let (fem, mut dem) = coupled_pair_with(run, zenoh_config).await;
        // 10k nodes (720 kB), then 10 nodes (720 B, under the shared-memory threshold)
        let sizes = [10_000, 10_000, 10_000, 10, 10];
        for (k, &n) in sizes.iter().enumerate() {
            fem.write_kinematics(&kinematics(run, k as u64, n))
                .await
                .unwrap();
            let got = dem
                .read_kinematics("top", Label::window(k as u64), n, Duration::from_secs(20))
                .await
                .unwrap();
            assert_eq!(got, kinematics(run, k as u64, n), "window {k}");
        }
        let (received, in_shm) = dem.data_received();
        assert_eq!(received, sizes.len() as u64);
        // the sender's own count: encoded straight into shared memory (zenoh would also copy
        // a large ordinary buffer into its pool, so the receiver's count alone does not tell)
        let (sent, sent_in_shm) = fem.data_sent();
        assert_eq!(sent, sizes.len() as u64);
        if expect_shm {
            assert_eq!(in_shm, 3, "the three large messages in shared memory");
            assert_eq!(sent_in_shm, 3, "encoded into shared memory by the sender");
        } else {
            assert_eq!(in_shm, 0, "shared memory is off");
            assert_eq!(sent_in_shm, 0, "shared memory is off");
        }
        fem.finish().await.unwrap();
        dem.finish().await.unwrap();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_missing_peer_is_a_timeout_error_not_a_hang() {
    let run = "link-missing";
    let p = free_loopback_port().unwrap();
    let mut dem = Participant::connect(
        &LinkConfig::loopback_peer(Some(p), &[]),
        run,
        "dem",
        hello(NodeKind::Dem),
    )
    .await
    .unwrap();
    dem.open_interfaces(&top()).await.unwrap();
    let t0 = Instant::now();
    let e = dem
        .read_kinematics("top", Label::window(0), 10, Duration::from_millis(500))
        .await
        .unwrap_err();
    assert!(matches!(e, ProtoError::Timeout { .. }), "{e}");
    assert!(e.to_string().contains("window 0"), "{e}");
    let e = dem
        .wait_for_peers(Duration::from_millis(300))
        .await
        .unwrap_err();
    assert!(e.to_string().contains("forces"), "{e}");
    let e = dem
        .read_mesh("top", Duration::from_millis(600))
        .await
        .unwrap_err();
    assert!(e.to_string().contains("interface mesh"), "{e}");
    assert!(t0.elapsed() < Duration::from_secs(10));
    dem.finish().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wrong_window_and_bad_sizes_are_refused_at_the_boundary() {
    let run = "link-refuse";
    let (fem, mut dem) = coupled_pair(run).await;
    fem.write_kinematics(&kinematics(run, 5, 4)).await.unwrap();
    let e = dem
        .read_kinematics("top", Label::window(4), 4, Duration::from_secs(5))
        .await
        .unwrap_err();
    assert!(
        matches!(
            e,
            ProtoError::WrongWindow {
                got: Label {
                    window: 5,
                    iteration: 0
                },
                expected: Label {
                    window: 4,
                    iteration: 0
                },
                ..
            }
        ),
        "{e}"
    );
    fem.write_kinematics(&kinematics(run, 6, 4)).await.unwrap();
    let e = dem
        .read_kinematics("top", Label::window(6), 5, Duration::from_secs(5))
        .await
        .unwrap_err();
    assert!(
        matches!(
            e,
            ProtoError::Size {
                got: 12,
                expected: 15,
                ..
            }
        ),
        "{e}"
    );
    fem.finish().await.unwrap();
    dem.finish().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_never_publishes_its_own_nan_it_reports_an_instability() {
    let run = "link-nan";
    let (fem, mut dem) = coupled_pair(run).await;
    // a small message (checked, then sent as a buffer) and a large one (checked while it is
    // encoded into shared memory), the bad value early, late or in the last field
    for (nodes, field, index, bad) in [
        (4, "velocities", 7, f64::NAN),
        (2000, "velocities", 4321, f64::INFINITY),
        (2000, "accelerations", 5999, f64::NEG_INFINITY),
        (2000, "positions", 0, -f64::NAN),
    ] {
        let mut k = kinematics(run, 0, nodes);
        match field {
            "positions" => k.positions.0[index] = bad,
            "velocities" => k.velocities.0[index] = bad,
            _ => k.accelerations.0[index] = bad,
        }
        let sent_before = fem.data_sent();
        let e = fem.write_kinematics(&k).await.unwrap_err();
        assert_eq!(fem.data_sent(), sent_before, "nothing was sent");
        assert!(
            matches!(
                &e,
                ProtoError::Diverged { field: f, index: i, .. } if *f == field && *i == index
            ),
            "{e}"
        );
        assert!(e.to_string().contains("the solver diverged"), "{e}");
        // the node loop reports it as an instability of this node, not as bad data of the other
        let n = proto::node::NodeError::from(e);
        assert_eq!(n.code, proto::ErrorCode::Unstable);
        // nothing was sent
        let e = dem
            .read_kinematics("top", Label::window(0), nodes, Duration::from_millis(300))
            .await
            .unwrap_err();
        assert!(matches!(e, ProtoError::Timeout { .. }), "{e}");
    }
    fem.finish().await.unwrap();
    dem.finish().await.unwrap();
}

fn advance(window: u64) -> proto::CommandBody {
    proto::CommandBody::AdvanceWindow(proto::AdvanceWindow {
        window,
        iteration: 0,
        t_start: window as f64 * 1e-4,
        dt: 1e-4,
        motion: proto::MotionRule::Quadratic,
        input: Some(Label::window(window)),
        output: None,
        static_solve: false,
    })
}

/// A coordinator link and a FEM and a DEM participant with interface `top` open; the DEM's
/// hello has said it queues commands, and it has taken window 0's `advance_window`.
async fn coordinated_pair(
    run: &str,
) -> (
    proto::participant::CoordinatorLink,
    Participant,
    Participant,
) {
    let (pc, pf, pd) = (
        free_loopback_port().unwrap(),
        free_loopback_port().unwrap(),
        free_loopback_port().unwrap(),
    );
    let mut coordinator =
        proto::participant::CoordinatorLink::open(&LinkConfig::loopback_peer(Some(pc), &[]), run)
            .await
            .unwrap();
    let mut fem = Participant::connect(
        &LinkConfig::loopback_peer(Some(pf), &[pc]),
        run,
        "fem",
        hello(NodeKind::Fem),
    )
    .await
    .unwrap();
    let mut dem = Participant::connect(
        &LinkConfig::loopback_peer(Some(pd), &[pf, pc]),
        run,
        "dem",
        hello(NodeKind::Dem),
    )
    .await
    .unwrap();
    // the DEM's hello says it queues commands (the participant adds it)
    loop {
        let ev = coordinator
            .next_event(Duration::from_secs(10), "hello from dem")
            .await
            .unwrap();
        if let proto::participant::Event::Status(st) = ev {
            if let proto::StatusBody::Hello(h) = &st.body {
                if st.node == "dem" {
                    assert!(
                        h.capabilities
                            .iter()
                            .any(|c| c == proto::CAPABILITY_QUEUED_COMMANDS),
                        "{h:?}"
                    );
                    break;
                }
            }
        }
    }
    fem.open_interfaces(&top()).await.unwrap();
    dem.open_interfaces(&top()).await.unwrap();
    fem.wait_for_peers(Duration::from_secs(10)).await.unwrap();
    dem.wait_for_peers(Duration::from_secs(10)).await.unwrap();

    coordinator.send("dem", advance(0)).await.unwrap();
    assert_eq!(
        dem.next_command(Some(Duration::from_secs(10)))
            .await
            .unwrap(),
        advance(0)
    );
    (coordinator, fem, dem)
}

/// The FEM publishes the kinematics of `window` after 300 ms (while the DEM waits).
fn write_later(
    fem: Participant,
    run: &'static str,
    window: u64,
) -> tokio::task::JoinHandle<Participant> {
    tokio::spawn(async move {
        tokio::time::sleep(Duration::from_millis(300)).await;
        fem.write_kinematics(&kinematics(run, window, 10))
            .await
            .unwrap();
        fem
    })
}

fn stop() -> proto::CommandBody {
    proto::CommandBody::Stop {
        reason: "test".into(),
    }
}

/// The coordinator announces windows ahead (`coupling.lookahead`): `advance_window`
/// commands that arrive while a node waits for its data are kept and served in order after
/// it; a `stop` that arrives meanwhile goes before them.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn windows_announced_while_a_node_waits_for_data_are_served_in_order() {
    let run = "link-ahead";
    let (mut coordinator, fem, mut dem) = coordinated_pair(run).await;
    // windows 1 and 2 announced while the DEM waits for window 0's kinematics
    coordinator.send("dem", advance(1)).await.unwrap();
    coordinator.send("dem", advance(2)).await.unwrap();
    let writer = write_later(fem, run, 0);
    let k = dem
        .read_kinematics("top", Label::window(0), 10, Duration::from_secs(10))
        .await
        .unwrap();
    assert_eq!(k, kinematics(run, 0, 10));
    let fem = writer.await.unwrap();
    for w in [1, 2] {
        let c = dem
            .next_command(Some(Duration::from_millis(1)))
            .await
            .unwrap();
        assert_eq!(c, advance(w), "served in order, without waiting");
    }
    // windows 3 and 4 announced during the next wait, then a stop while the node would
    // compute: the stop goes before the windows kept
    coordinator.send("dem", advance(3)).await.unwrap();
    coordinator.send("dem", advance(4)).await.unwrap();
    let writer = write_later(fem, run, 1);
    dem.read_kinematics("top", Label::window(1), 10, Duration::from_secs(10))
        .await
        .unwrap();
    let fem = writer.await.unwrap();
    coordinator.send("dem", stop()).await.unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(
        dem.next_command(Some(Duration::from_secs(10)))
            .await
            .unwrap(),
        stop()
    );
    dem.finish().await.unwrap();
    fem.finish().await.unwrap();
    coordinator.close().await.unwrap();
}

/// A `stop` behind an announced window ends a data wait at once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stop_behind_announced_windows_ends_the_wait_for_data() {
    let run = "link-ahead-stop";
    let (mut coordinator, fem, mut dem) = coordinated_pair(run).await;
    coordinator.send("dem", advance(1)).await.unwrap();
    coordinator.send("dem", stop()).await.unwrap();
    let t0 = Instant::now();
    let e = dem
        .read_kinematics("top", Label::window(0), 10, Duration::from_secs(10))
        .await
        .unwrap_err();
    assert!(
        matches!(&e, ProtoError::Stopped { reason } if reason == "test"),
        "{e}"
    );
    assert!(t0.elapsed() < Duration::from_secs(5));
    dem.finish().await.unwrap();
    fem.finish().await.unwrap();
    coordinator.close().await.unwrap();
}

/// A flat `n × n` grid of interface nodes with two triangles per cell.
fn grid_mesh(run: &str, n: usize) -> proto::InterfaceMesh {
    let mut positions = Vec::with_capacity(3 * n * n);
    for j in 0..n {
        for i in 0..n {
            positions.extend([i as f64 * 1e-3, j as f64 * 1e-3, 0.0]);
        }
    }
    let mut triangles = Vec::new();
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = (j * n + i) as u32;
            let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
            triangles.extend([a, b, d, a, d, c]);
        }
    }
    proto::InterfaceMesh {
        version: PROTOCOL_VERSION,
        run_id: run.into(),
        interface: "top".into(),
        node_ids: (1..=(n * n) as u64).collect(),
        positions: positions.into(),
        triangles,
        volume: None,
    }
}

/// On one host the run's links are zenoh's low-latency links (LinkConfig::lowlatency), which
/// carry at most one 64 kB batch per message outside shared memory: a command, a mesh and
/// interface data far larger than that still arrive whole and in order (the participant puts
/// them in the pool explicitly). A partner that does not ask for low-latency links (here:
/// one opened from a zenoh configuration file, like the Python node or another machine) gets
/// an ordinary link and the same messages.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn messages_larger_than_a_low_latency_batch_arrive_whole() {
    let lowlatency = LinkConfig::loopback_peer(Some(1), &[]).lowlatency();
    if !lowlatency {
        eprintln!("this host has too little room in /dev/shm: ordinary links only");
    }
    // coordinator → node: an `init` whose scene is 300 kB
    let run = "link-big";
    let (mut coordinator, fem, mut dem) = coordinated_pair(run).await;
    let scene: String = (0..20_000).map(|i| format!("# line {i:08}\n")).collect();
    assert!(scene.len() > 250_000);
    let init = proto::CommandBody::Init(proto::Init {
        scene_path: "big.toml".into(),
        scene_toml: scene,
        table: "dem".into(),
        out_dir: "out".into(),
        interfaces: top(),
        check_only: false,
        trace: false,
    });
    coordinator.send("dem", init.clone()).await.unwrap();
    assert_eq!(
        dem.next_command(Some(Duration::from_secs(10)))
            .await
            .unwrap(),
        init
    );
    // FEM → DEM: a 40,000-node mesh (about 2.3 MB) and 100,000-node kinematics (7.2 MB each),
    // sent four at a time before the reader takes any
    let (mut fem, mut dem) = (fem, dem);
    let mesh = grid_mesh(run, 200);
    fem.provide_mesh(&mesh).await.unwrap();
    assert_eq!(
        dem.read_mesh("top", Duration::from_secs(20)).await.unwrap(),
        mesh
    );
    const NODES: usize = 100_000;
    let sender = tokio::spawn(async move {
        for k in 1..=4 {
            fem.write_kinematics(&kinematics(run, k, NODES))
                .await
                .unwrap();
        }
        fem
    });
    for k in 1..=4 {
        let got = dem
            .read_kinematics("top", Label::window(k), NODES, Duration::from_secs(30))
            .await
            .unwrap();
        assert_eq!(got, kinematics(run, k, NODES), "window {k}");
    }
    let fem = sender.await.unwrap();
    if lowlatency {
        assert_eq!(fem.data_sent(), (4, 4), "all four in shared memory");
    }
    fem.finish().await.unwrap();
    dem.finish().await.unwrap();
    coordinator.close().await.unwrap();

    // a low-latency FEM and a DEM opened from a configuration file: an ordinary link
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("zenoh.json5");
    std::fs::write(&file, "{ }").unwrap();
    let run = "link-mixed";
    let (pf, pd) = (free_loopback_port().unwrap(), free_loopback_port().unwrap());
    let fem_link = LinkConfig::loopback_peer(Some(pf), &[]);
    let dem_link = LinkConfig {
        zenoh_config: Some(file),
        ..LinkConfig::loopback_peer(Some(pd), &[pf])
    };
    assert_eq!(fem_link.lowlatency(), lowlatency);
    assert!(!dem_link.lowlatency());
    let mut fem = Participant::connect(&fem_link, run, "fem", hello(NodeKind::Fem))
        .await
        .unwrap();
    let mut dem = Participant::connect(&dem_link, run, "dem", hello(NodeKind::Dem))
        .await
        .unwrap();
    fem.open_interfaces(&top()).await.unwrap();
    dem.open_interfaces(&top()).await.unwrap();
    fem.wait_for_peers(Duration::from_secs(10)).await.unwrap();
    dem.wait_for_peers(Duration::from_secs(10)).await.unwrap();
    let mesh = grid_mesh(run, 200);
    fem.provide_mesh(&mesh).await.unwrap();
    assert_eq!(
        dem.read_mesh("top", Duration::from_secs(20)).await.unwrap(),
        mesh
    );
    for k in 0..3 {
        fem.write_kinematics(&kinematics(run, k, NODES))
            .await
            .unwrap();
        let got = dem
            .read_kinematics("top", Label::window(k), NODES, Duration::from_secs(30))
            .await
            .unwrap();
        assert_eq!(got, kinematics(run, k, NODES), "window {k}");
    }
    fem.finish().await.unwrap();
    dem.finish().await.unwrap();
}
