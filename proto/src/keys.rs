//! Key expressions of a run. Every key is `cosim/<run-id>/…`; this module is the only place
//! that spells them (PROTOCOL.md, "Keys").

use crate::ProtoError;

/// Checks a run id, node name or interface name: 1–64 characters of `A-Z a-z 0-9 _ -`, so it
/// can never contain a key-expression separator or wildcard.
pub fn validate_name(what: &'static str, name: &str) -> Result<(), ProtoError> {
    let ok = !name.is_empty()
        && name.len() <= 64
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
    if ok {
        Ok(())
    } else {
        Err(ProtoError::Name {
            what,
            name: name.to_string(),
        })
    }
}

/// The key expressions of one run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Keys {
    run_id: String,
}

impl Keys {
    pub fn new(run_id: &str) -> Result<Self, ProtoError> {
        validate_name("run id", run_id)?;
        Ok(Keys {
            run_id: run_id.to_string(),
        })
    }

    pub fn run_id(&self) -> &str {
        &self.run_id
    }

    /// Everything of the run: `cosim/<run>/**`.
    pub fn all(&self) -> String {
        format!("cosim/{}/**", self.run_id)
    }

    /// Commands from the coordinator to one node.
    pub fn command(&self, node: &str) -> String {
        format!("cosim/{}/cmd/{}", self.run_id, node)
    }

    /// Status messages (hello, ready, window done, error, stopped) from one node.
    pub fn status(&self, node: &str) -> String {
        format!("cosim/{}/status/{}", self.run_id, node)
    }

    /// Status of every node (the coordinator subscribes here).
    pub fn status_all(&self) -> String {
        format!("cosim/{}/status/*", self.run_id)
    }

    /// Liveliness token of one node.
    pub fn alive(&self, node: &str) -> String {
        format!("cosim/{}/alive/{}", self.run_id, node)
    }

    /// Liveliness tokens of every node.
    pub fn alive_all(&self) -> String {
        format!("cosim/{}/alive/*", self.run_id)
    }

    /// Interface mesh (queryable of the FEM node).
    pub fn mesh(&self, interface: &str) -> String {
        format!("cosim/{}/iface/{}/mesh", self.run_id, interface)
    }

    /// Interface forces, DEM → FEM.
    pub fn forces(&self, interface: &str) -> String {
        format!("cosim/{}/iface/{}/forces", self.run_id, interface)
    }

    /// Interface forces accelerated by the coordinator (implicit schemes), coordinator → the
    /// interface's provider.
    pub fn relaxed_forces(&self, interface: &str) -> String {
        format!("cosim/{}/iface/{}/forces_relaxed", self.run_id, interface)
    }

    /// The users' interface forces of every interface (the coordinator's reliable tap).
    pub fn forces_all(&self) -> String {
        format!("cosim/{}/iface/*/forces", self.run_id)
    }

    /// Interface kinematics, FEM → DEM.
    pub fn kinematics(&self, interface: &str) -> String {
        format!("cosim/{}/iface/{}/kinematics", self.run_id, interface)
    }

    /// Interface kinematics estimated by the coordinator (concurrent implicit scheme),
    /// coordinator → the interface's users.
    pub fn relaxed_kinematics(&self, interface: &str) -> String {
        format!(
            "cosim/{}/iface/{}/kinematics_relaxed",
            self.run_id, interface
        )
    }

    /// The providers' kinematics of every interface (the coordinator's reliable tap).
    pub fn kinematics_all(&self) -> String {
        format!("cosim/{}/iface/*/kinematics", self.run_id)
    }

    /// All interface data of the run (the coordinator's monitor).
    pub fn iface_all(&self) -> String {
        format!("cosim/{}/iface/**", self.run_id)
    }

    /// Node name from a status or liveliness key of this run, if the key is one.
    pub fn node_of(&self, key: &str) -> Option<String> {
        let rest = key
            .strip_prefix("cosim/")?
            .strip_prefix(self.run_id.as_str())?;
        let rest = rest.strip_prefix('/')?;
        let (kind, node) = rest.split_once('/')?;
        (matches!(kind, "status" | "alive" | "cmd") && validate_name("node", node).is_ok())
            .then(|| node.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_are_under_the_run() {
        let k = Keys::new("run-1").unwrap();
        assert_eq!(k.forces("top"), "cosim/run-1/iface/top/forces");
        assert_eq!(k.node_of(&k.status("dem")), Some("dem".into()));
        assert_eq!(k.node_of(&k.alive("fem_1")), Some("fem_1".into()));
        assert_eq!(k.node_of("cosim/other/status/dem"), None);
    }

    #[test]
    fn names_with_separators_or_wildcards_are_refused() {
        for bad in ["", "a/b", "*", "a**", "ä", &"x".repeat(65)] {
            assert!(Keys::new(bad).is_err(), "{bad}");
        }
    }
}
