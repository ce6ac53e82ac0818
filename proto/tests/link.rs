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
    let (pf, pd) = (free_loopback_port().unwrap(), free_loopback_port().unwrap());
    let ifaces = top();
    let fem_link = LinkConfig::loopback_peer(Some(pf), &[]);
    let mut fem = Participant::connect(&fem_link, run, "fem", hello(NodeKind::Fem))
        .await
        .unwrap();
    let dem_link = LinkConfig::loopback_peer(Some(pd), &[pf]);
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
    let mut k = kinematics(run, 0, 4);
    k.velocities.0[7] = f64::NAN;
    let e = fem.write_kinematics(&k).await.unwrap_err();
    assert!(
        matches!(
            e,
            ProtoError::Diverged {
                field: "velocities",
                index: 7,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("the solver diverged"), "{e}");
    // the node loop reports it as an instability of this node, not as bad data of the other
    let n = proto::node::NodeError::from(e);
    assert_eq!(n.code, proto::ErrorCode::Unstable);
    // nothing was sent
    let e = dem
        .read_kinematics("top", Label::window(0), 4, Duration::from_millis(300))
        .await
        .unwrap_err();
    assert!(matches!(e, ProtoError::Timeout { .. }), "{e}");
    fem.finish().await.unwrap();
    dem.finish().await.unwrap();
}
