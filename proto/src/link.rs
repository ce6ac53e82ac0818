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
        Ok(config)
    }

    /// Opens the session.
    pub async fn open(&self) -> Result<zenoh::Session, ProtoError> {
        let config = self.to_zenoh_config()?;
        zenoh::open(config).await.map_err(ProtoError::zenoh)
    }
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
