//! Command-line flags every node understands (the coordinator appends them when it starts a
//! node), so that an adapter's `main` is a few lines.

use std::path::PathBuf;
use std::time::Duration;

use crate::link::{LinkConfig, LinkMode};

#[derive(Debug, Clone, clap::Args)]
pub struct NodeArgs {
    /// Run to join (the coordinator prints it).
    #[arg(long)]
    pub run_id: String,
    /// Id of this node in the run (`dem`, `fem`, or a structure's id the scene declares).
    #[arg(long)]
    pub node: String,
    /// Endpoint to listen on, e.g. tcp/127.0.0.1:7448 (repeatable).
    #[arg(long)]
    pub listen: Vec<String>,
    /// Endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable).
    #[arg(long)]
    pub connect: Vec<String>,
    /// zenoh configuration file (client of a router, TLS, credentials): see deploy/.
    #[arg(long)]
    pub zenoh_config: Option<PathBuf>,
    /// `peer` (default) or `client`.
    #[arg(long, default_value = "peer", value_parser = ["peer", "client"])]
    pub mode: String,
    /// Longest wait for the other solver's interface data in one window (s).
    #[arg(long, default_value_t = 600.0)]
    pub data_timeout: f64,
}

impl NodeArgs {
    /// The link this node opens; the lease from `COSIM_LINK_LEASE_MS` when the coordinator
    /// that started the node gives one ([`crate::link::LEASE_ENV`]), else 3 s.
    pub fn link(&self) -> Result<LinkConfig, crate::ProtoError> {
        // a configuration file sets its own lease (the variable is then not read)
        let lease = match &self.zenoh_config {
            None => crate::link::lease_from_env()?,
            Some(_) => None,
        }
        .unwrap_or(LinkConfig::default().lease);
        Ok(LinkConfig {
            mode: if self.mode == "client" || self.zenoh_config.is_some() && self.mode != "peer" {
                LinkMode::Client
            } else {
                LinkMode::Peer
            },
            listen: self.listen.clone(),
            connect: self.connect.clone(),
            zenoh_config: self.zenoh_config.clone(),
            lease,
        })
    }

    pub fn data_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.data_timeout.max(0.001))
    }
}
