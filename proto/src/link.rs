//! Opening a zenoh session for a run (PROTOCOL.md, "Transport").
//!
//! Defaults follow the network rules of the project: peer mode, explicit `tcp/127.0.0.1:<port>`
//! endpoints, multicast scouting **always off** (also when a config file is given), a short
//! lease so that a dead node is noticed within seconds.

use std::path::PathBuf;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use zenoh::Config;

use crate::ProtoError;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum LinkMode {
    /// Direct links between the run's processes (one machine, or a few with explicit endpoints).
    #[default]
    Peer,
    /// Connect to a zenoh router (`zenohd`), for runs over several machines (`deploy/`).
    Client,
}

/// How a process joins the zenoh network of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinkConfig {
    pub mode: LinkMode,
    /// Endpoints to listen on, e.g. `tcp/127.0.0.1:7447`.
    pub listen: Vec<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// A zenoh JSON5 configuration file (TLS, credentials, ...). Its settings are the base;
    /// `mode`, `listen` and `connect` above override it when non-empty, and multicast
    /// scouting is switched off regardless.
    pub zenoh_config: Option<PathBuf>,
    /// Lease of the transport links: a peer silent for this long is declared gone.
    pub lease: Duration,
}

/// Lease of the links between processes on one host when the coordinator starts them all
/// (`cosim run` without `--listen` or `--zenoh-config`). On one host a process that dies is
/// seen at once (its sockets close, the coordinator reaps it, a node watches the coordinator's
/// process): the lease only guards against a silent peer, and a short one turned a process
/// starved of CPU for a few seconds (a busy machine, a run at low priority) into a "dead" node
/// and lost the run.
pub const LOCAL_LEASE: Duration = Duration::from_secs(30);

/// The coordinator gives the nodes it starts their links' lease here (milliseconds), so that
/// the node programs need no new flag; a node started by hand does not have it and keeps the
/// default 3 s.
pub const LEASE_ENV: &str = "COSIM_LINK_LEASE_MS";

/// The lease `COSIM_LINK_LEASE_MS` asks for: `None` when it is unset; an error naming the
/// variable when it is not a whole number of milliseconds in 100..=3,600,000.
pub fn lease_from_env() -> Result<Option<Duration>, ProtoError> {
    let Some(v) = std::env::var_os(LEASE_ENV) else {
        return Ok(None);
    };
    parse_lease(&v.to_string_lossy()).map(Some)
}

/// A lease in whole milliseconds, 100 to 3,600,000 (the text of [`LEASE_ENV`]).
fn parse_lease(text: &str) -> Result<Duration, ProtoError> {
    match text.trim().parse::<u64>() {
        Ok(ms) if (100..=3_600_000).contains(&ms) => Ok(Duration::from_millis(ms)),
        _ => Err(ProtoError::Config(format!(
            "{LEASE_ENV}={text}: give the links' lease in whole milliseconds, 100 to 3600000"
        ))),
    }
}

impl Default for LinkConfig {
    fn default() -> Self {
        LinkConfig {
            mode: LinkMode::Peer,
            listen: Vec::new(),
            connect: Vec::new(),
            zenoh_config: None,
            lease: Duration::from_millis(3000),
        }
    }
}

fn json_list(items: &[String]) -> String {
    serde_json::to_string(items).expect("strings serialise")
}

/// Checks an endpoint: `proto/address:port`, with a known transport.
pub fn validate_endpoint(endpoint: &str) -> Result<(), ProtoError> {
    let (proto, rest) = endpoint.split_once('/').ok_or_else(|| {
        ProtoError::Config(format!(
            "endpoint `{endpoint}` lacks a transport prefix such as `tcp/`"
        ))
    })?;
    if !matches!(
        proto,
        "tcp" | "tls" | "udp" | "quic" | "unixsock-stream" | "ws"
    ) {
        return Err(ProtoError::Config(format!(
            "endpoint `{endpoint}`: unknown transport `{proto}`"
        )));
    }
    if proto != "unixsock-stream" && !rest.contains(':') {
        return Err(ProtoError::Config(format!(
            "endpoint `{endpoint}` lacks a port (`{proto}/host:port`)"
        )));
    }
    Ok(())
}

impl LinkConfig {
    /// A peer on loopback listening on `listen_port` and connecting to the given loopback ports.
    pub fn loopback_peer(listen_port: Option<u16>, connect_ports: &[u16]) -> Self {
        LinkConfig {
            listen: listen_port
                .map(|p| vec![format!("tcp/127.0.0.1:{p}")])
                .unwrap_or_default(),
            connect: connect_ports
                .iter()
                .map(|p| format!("tcp/127.0.0.1:{p}"))
                .collect(),
            ..Default::default()
        }
    }

    /// The zenoh configuration this link opens with.
    pub fn to_zenoh_config(&self) -> Result<Config, ProtoError> {
        self.zenoh_config_for(self.lowlatency())
    }

    /// The zenoh configuration, with low-latency links asked for or not.
    fn zenoh_config_for(&self, lowlatency: bool) -> Result<Config, ProtoError> {
        let mut config = match &self.zenoh_config {
            Some(path) => Config::from_file(path).map_err(|e| {
                ProtoError::Config(format!("zenoh config file {}: {e}", path.display()))
            })?,
            None => Config::default(),
        };
        let set = |config: &mut Config, key: &str, value: String| {
            config
                .insert_json5(key, &value)
                .map_err(|e| ProtoError::Config(format!("setting `{key}` to {value}: {e}")))
        };
        if self.zenoh_config.is_none() || self.mode == LinkMode::Client {
            let mode = match self.mode {
                LinkMode::Peer => "\"peer\"",
                LinkMode::Client => "\"client\"",
            };
            set(&mut config, "mode", mode.to_string())?;
        }
        for e in self.listen.iter().chain(&self.connect) {
            validate_endpoint(e)?;
        }
        if !self.listen.is_empty() || self.zenoh_config.is_none() {
            // without a file and without --listen: listen nowhere (zenoh's own peer default
            // would be every interface)
            set(&mut config, "listen/endpoints", json_list(&self.listen))?;
        }
        if !self.connect.is_empty() {
            set(&mut config, "connect/endpoints", json_list(&self.connect))?;
        }
        // Nothing may leave the machine unless configured: no multicast scouting, ever.
        set(&mut config, "scouting/multicast/enabled", "false".into())?;
        if self.zenoh_config.is_none() {
            set(
                &mut config,
                "transport/link/tx/lease",
                self.lease.as_millis().max(100).to_string(),
            )?;
            set(&mut config, "transport/link/tx/keep_alive", "4".into())?;
        }
        if lowlatency {
            set(&mut config, "transport/unicast/lowlatency", "true".into())?;
            set(&mut config, "transport/unicast/qos/enabled", "false".into())?;
            set(
                &mut config,
                "transport/shared_memory/enabled",
                "true".into(),
            )?;
            set(
                &mut config,
                "transport/shared_memory/transport_optimization/pool_size",
                LOWLATENCY_POOL_BYTES.to_string(),
            )?;
        }
        Ok(config)
    }

    /// Whether this session asks for zenoh's low-latency links: each message is written to the
    /// socket by the thread that sends it (no batching task to wake), which takes about 10 µs
    /// off each hop and 60 % off a coupling window's coordination (docs/performance.md).
    ///
    /// A low-latency link carries at most one batch (64 kB) per message outside shared memory,
    /// so it is asked for only where the partners can share this host's memory: without a
    /// zenoh config file, in peer mode, with every endpoint on loopback, with room for
    /// [`SHM_SEGMENTS`] pools in `/dev/shm`, and allowed to lock them in memory (zenoh
    /// `mlock`s its own pool and every partner's it maps: root, or `ulimit -l` large enough).
    /// Larger messages then go through the pool explicitly (the participant waits for room
    /// rather than send them inline). A link whose other end does not ask for it (the Python
    /// node, an external solver) is an ordinary link: zenoh negotiates it per link.
    /// `COSIM_LOWLATENCY=0` (or `off`, `false`, `no`) in the environment switches it off.
    pub fn lowlatency(&self) -> bool {
        self.lowlatency_given(
            std::env::var("COSIM_LOWLATENCY").ok().as_deref(),
            shm_free_bytes("/dev/shm"),
            lockable_bytes(),
        )
    }

    /// [`Self::lowlatency`] for a given `COSIM_LOWLATENCY`, free space in `/dev/shm` and
    /// lockable memory (`None`: unlimited).
    fn lowlatency_given(
        &self,
        env: Option<&str>,
        shm_free: Option<u64>,
        lockable: Option<u64>,
    ) -> bool {
        let mut endpoints = self.listen.iter().chain(&self.connect).peekable();
        let needed = SHM_SEGMENTS * LOWLATENCY_POOL_BYTES as u64;
        let switched_off = env.is_some_and(|v| {
            matches!(
                v.trim().to_ascii_lowercase().as_str(),
                "0" | "off" | "false" | "no"
            )
        });
        self.zenoh_config.is_none()
            && self.mode == LinkMode::Peer
            && endpoints.peek().is_some()
            && endpoints.all(|e| is_loopback_endpoint(e))
            && !switched_off
            && shm_free.is_some_and(|free| free >= needed)
            && lockable.is_none_or(|l| l >= needed)
    }

    /// Opens the session.
    pub async fn open(&self) -> Result<zenoh::Session, ProtoError> {
        Ok(self.open_with_mode().await?.0)
    }

    /// Opens the session; also says whether it asked for low-latency links (decided once, so
    /// that the session and its sender agree on it).
    pub async fn open_with_mode(&self) -> Result<(zenoh::Session, bool), ProtoError> {
        let config = self.zenoh_config_for(self.lowlatency())?;
        // read back: a configuration file may ask for low-latency links itself
        let lowlatency = config
            .get_json("transport/unicast/lowlatency")
            .is_ok_and(|v| v.trim() == "true");
        let session = zenoh::open(config).await.map_err(ProtoError::zenoh)?;
        Ok((session, lowlatency))
    }
}

/// The shared-memory pool of a session on low-latency links (zenoh's transport pool, which
/// the participant's large messages are allocated from): a message larger than this cannot be
/// sent on them.
pub const LOWLATENCY_POOL_BYTES: usize = 64 << 20;

/// Shared-memory segments a process of a run may lock (its own pool and the partners' it
/// maps): the room [`LinkConfig::lowlatency`] asks for in `/dev/shm` and in `ulimit -l`.
pub const SHM_SEGMENTS: u64 = 4;

/// The largest message sent inline on a low-latency link: one batch is 64 kB with zenoh's
/// headers; anything larger must travel in shared memory.
pub const LOWLATENCY_INLINE_MAX: usize = 48 << 10;

/// A `tcp/` or `unixsock-stream/` endpoint on this host (127.0.0.0/8, `localhost`, `[::1]`).
pub fn is_loopback_endpoint(endpoint: &str) -> bool {
    let Some((proto, rest)) = endpoint.split_once('/') else {
        return false;
    };
    // locator metadata and configuration follow `?` and `#`
    let address = rest.split(['?', '#']).next().unwrap_or("");
    match proto {
        "unixsock-stream" => true,
        "tcp" => {
            let host = match address.rsplit_once(':') {
                Some((host, _port)) => host,
                None => return false,
            };
            let host = host.trim_start_matches('[').trim_end_matches(']');
            host == "localhost"
                || host
                    .parse::<std::net::IpAddr>()
                    .is_ok_and(|ip| ip.is_loopback())
        }
        _ => false,
    }
}

/// Bytes this process may lock in memory (`RLIMIT_MEMLOCK`); `None` when unlimited (root, or
/// `ulimit -l unlimited`).
fn lockable_bytes() -> Option<u64> {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } == 0 {
        return None;
    }
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `lim` is a valid, writable rlimit.
    if unsafe { libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut lim) } != 0 {
        return Some(0);
    }
    (lim.rlim_cur != libc::RLIM_INFINITY).then_some(lim.rlim_cur)
}

/// Bytes free to an unprivileged writer on the file system holding `path`.
fn shm_free_bytes(path: &str) -> Option<u64> {
    let c = std::ffi::CString::new(path).ok()?;
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: `c` is a NUL-terminated path and `st` a valid, writable statvfs.
    if unsafe { libc::statvfs(c.as_ptr(), &mut st) } != 0 {
        return None;
    }
    Some((st.f_bavail as u64).saturating_mul(st.f_frsize as u64))
}

/// A free TCP port on 127.0.0.1 for a process started next to listen on.
///
/// The port is released before the process binds it, so it must not be one the kernel hands to
/// outgoing connections in between: with many runs at once (`cosim study --jobs`, the test
/// suite) a zenoh session connecting elsewhere could take an ephemeral port and the node would
/// fail to listen. Ports are therefore picked below the ephemeral range
/// (`/proc/sys/net/ipv4/ip_local_port_range`, default 32768–60999), from a per-process random
/// start, and each candidate is checked by binding it. Only when none of those is free does the
/// kernel choose (port 0).
pub fn free_loopback_port() -> std::io::Result<u16> {
    use std::sync::atomic::{AtomicU32, Ordering};
    static NEXT: AtomicU32 = AtomicU32::new(0);
    let (lo, hi) = picking_range();
    let span = u32::from(hi - lo);
    let start = *PICK_START.get_or_init(|| random_u32() % span);
    for _ in 0..256 {
        let k = NEXT.fetch_add(1, Ordering::Relaxed);
        let port = lo + ((start + k.wrapping_mul(7919)) % span) as u16;
        if let Ok(l) = std::net::TcpListener::bind(("127.0.0.1", port)) {
            return Ok(l.local_addr()?.port());
        }
    }
    let l = std::net::TcpListener::bind(("127.0.0.1", 0))?;
    Ok(l.local_addr()?.port())
}

static PICK_START: std::sync::OnceLock<u32> = std::sync::OnceLock::new();

/// Ports `[lo, hi)` [`free_loopback_port`] picks from: up to 16,384 ports just below the
/// kernel's ephemeral range, never below 1024.
fn picking_range() -> (u16, u16) {
    let ephemeral_lo = std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<u16>().ok())
        .unwrap_or(32768);
    let hi = ephemeral_lo.max(1024 + 256);
    (hi.saturating_sub(16384).max(1024), hi)
}

/// A per-process random number (std's randomly keyed hasher, the clock and the pid).
fn random_u32() -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u32(std::process::id());
    if let Ok(d) = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH) {
        h.write_u128(d.as_nanos());
    }
    h.finish() as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lease_variable_takes_whole_milliseconds_in_range_and_names_itself_otherwise() {
        assert_eq!(parse_lease("30000").unwrap(), Duration::from_secs(30));
        assert_eq!(parse_lease(" 100\n").unwrap(), Duration::from_millis(100));
        for bad in ["", "3.5", "-1", "99", "3600001", "30s"] {
            let e = parse_lease(bad).unwrap_err().to_string();
            assert!(e.contains(LEASE_ENV), "{bad}: {e}");
        }
        // the lease reaches zenoh's configuration
        let c = LinkConfig {
            lease: LOCAL_LEASE,
            ..LinkConfig::loopback_peer(Some(7000), &[])
        }
        .to_zenoh_config()
        .unwrap();
        let v: serde_json::Value = serde_json::from_str(&format!("{c}")).unwrap();
        assert_eq!(v["transport"]["link"]["tx"]["lease"], 30000);
    }

    #[test]
    fn default_config_has_multicast_off_and_explicit_endpoints() {
        let c = LinkConfig::loopback_peer(Some(7000), &[7001])
            .to_zenoh_config()
            .unwrap();
        let json = format!("{c}");
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert_eq!(v["scouting"]["multicast"]["enabled"], false);
        assert_eq!(
            v["listen"]["endpoints"],
            serde_json::json!(["tcp/127.0.0.1:7000"])
        );
        assert_eq!(
            v["connect"]["endpoints"],
            serde_json::json!(["tcp/127.0.0.1:7001"])
        );
    }

    #[test]
    fn without_listen_endpoints_a_peer_listens_nowhere() {
        let c = LinkConfig::loopback_peer(None, &[7001])
            .to_zenoh_config()
            .unwrap();
        let v: serde_json::Value = serde_json::from_str(&format!("{c}")).unwrap();
        assert_eq!(v["listen"]["endpoints"], serde_json::json!([]));
    }

    #[test]
    fn free_ports_lie_below_the_ephemeral_range_and_are_free() {
        let (lo, hi) = picking_range();
        assert!(1024 <= lo && lo < hi, "{lo}..{hi}");
        let mut seen = std::collections::BTreeSet::new();
        let mut held = Vec::new();
        for _ in 0..20 {
            let p = free_loopback_port().unwrap();
            assert!((lo..hi).contains(&p), "{p} outside {lo}..{hi}");
            assert!(seen.insert(p), "{p} handed out twice");
            // the port is really free: it can be bound (and is kept bound, so the next pick
            // must skip it)
            held.push(std::net::TcpListener::bind(("127.0.0.1", p)).unwrap());
        }
    }

    #[test]
    fn loopback_endpoints_are_told_from_others() {
        for e in [
            "tcp/127.0.0.1:7447",
            "tcp/127.3.2.1:1",
            "tcp/localhost:7000",
            "tcp/[::1]:7000",
            "tcp/127.0.0.1:7447#iface=lo",
            "unixsock-stream//tmp/cosim.sock",
        ] {
            assert!(is_loopback_endpoint(e), "{e}");
        }
        for e in [
            "tcp/10.0.0.2:7447",
            "tcp/192.0.2.7:7447",
            "tcp/[2001:db8::7]:7447",
            "tcp/example.org:7447",
            "tls/127.0.0.1:7447",
            "udp/127.0.0.1:7447",
            "tcp/127.0.0.1",
            "127.0.0.1:7447",
        ] {
            assert!(!is_loopback_endpoint(e), "{e}");
        }
    }

    #[test]
    fn low_latency_links_only_between_loopback_peers_with_shared_memory() {
        let room = Some(SHM_SEGMENTS * LOWLATENCY_POOL_BYTES as u64);
        let local = LinkConfig::loopback_peer(Some(7000), &[7001]);
        assert!(local.lowlatency_given(None, room, None));
        assert!(local.lowlatency_given(Some("1"), room, room));
        // switched off, no /dev/shm, too little room in it or too little lockable memory
        // (an ordinary user's default `ulimit -l` of 8 MB)
        for off in ["0", " off", "FALSE", "no"] {
            assert!(!local.lowlatency_given(Some(off), room, None), "{off}");
        }
        assert!(!local.lowlatency_given(None, None, None));
        assert!(!local.lowlatency_given(None, Some(LOWLATENCY_POOL_BYTES as u64), None));
        assert!(!local.lowlatency_given(None, room, Some(8 << 20)));
        // one endpoint off this host, a router, a configuration file, no endpoint at all
        let mut remote = local.clone();
        remote.connect.push("tcp/10.0.0.2:7447".into());
        assert!(!remote.lowlatency_given(None, room, None));
        let client = LinkConfig {
            mode: LinkMode::Client,
            ..local.clone()
        };
        assert!(!client.lowlatency_given(None, room, None));
        let file = LinkConfig {
            zenoh_config: Some("zenoh.json5".into()),
            ..local.clone()
        };
        assert!(!file.lowlatency_given(None, room, None));
        assert!(!LinkConfig::default().lowlatency_given(None, room, None));
    }

    #[test]
    fn a_low_latency_config_switches_qos_off_and_sizes_the_pool() {
        let link = LinkConfig::loopback_peer(Some(7000), &[]);
        let v: serde_json::Value =
            serde_json::from_str(&format!("{}", link.to_zenoh_config().unwrap())).unwrap();
        let unicast = &v["transport"]["unicast"];
        assert_eq!(
            link.zenoh_config_for(true)
                .unwrap()
                .get_json("transport/unicast/lowlatency")
                .unwrap(),
            "true"
        );
        if link.lowlatency() {
            assert_eq!(unicast["lowlatency"], true);
            assert_eq!(unicast["qos"]["enabled"], false);
            assert_eq!(
                v["transport"]["shared_memory"]["transport_optimization"]["pool_size"],
                LOWLATENCY_POOL_BYTES
            );
        } else {
            assert_eq!(unicast["lowlatency"], false);
        }
    }

    #[test]
    fn bad_endpoints_are_refused_with_the_endpoint_named() {
        for bad in ["127.0.0.1:7000", "foo/127.0.0.1:1", "tcp/127.0.0.1"] {
            let e = LinkConfig {
                listen: vec![bad.into()],
                ..Default::default()
            }
            .to_zenoh_config()
            .unwrap_err();
            assert!(e.to_string().contains(bad), "{e}");
        }
    }
}
