//! The solver-facing API, in the spirit of preCICE's `Participant`: a solver joins a run with
//! [`Participant::connect`], receives commands with [`Participant::next_command`], reads and
//! writes interface data for a window, reports its status, and [`Participant::finish`]es.
//!
//! The coordinator's side of the same wire is [`CoordinatorLink`].

use std::collections::HashMap;
use std::time::{Duration, Instant};

use zenoh::handlers::FifoChannelHandler;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::CongestionControl;
use zenoh::query::Queryable;
use zenoh::sample::{Sample, SampleKind};
use zenoh::Wait;

use crate::codec::{decode, decode_finite, encode, encode_into_checked, encoded_len, Message};
use crate::keys::{validate_name, Keys};
use crate::link::{LinkConfig, LOWLATENCY_INLINE_MAX, LOWLATENCY_POOL_BYTES};
use crate::messages::*;
use crate::ProtoError;

/// Queue length of data subscribers: windows are consumed one at a time, a few may queue.
const DATA_QUEUE: usize = 8;
const CONTROL_QUEUE: usize = 256;

/// Node name of the coordinator's liveliness token (reserved).
pub const COORDINATOR: &str = "coordinator";

fn payload(sample: &Sample) -> std::borrow::Cow<'_, [u8]> {
    sample.payload().to_bytes()
}

async fn declare_data_publisher(
    session: &zenoh::Session,
    key: String,
) -> Result<Publisher<'static>, ProtoError> {
    // Interface data must never be dropped: block the sender rather than lose a window.
    session
        .declare_publisher(key)
        .congestion_control(CongestionControl::Block)
        .express(true)
        .await
        .map_err(ProtoError::zenoh)
}

/// Sends a message as an ordinary buffer — unless it is too large for a low-latency link, in
/// which case it goes through the session's shared-memory pool ([`ShmSend::alloc_required`]).
async fn put<M: Message>(
    publisher: &Publisher<'static>,
    msg: &M,
    session: &zenoh::Session,
    shm: &ShmSend,
) -> Result<(), ProtoError> {
    let payload = shm.payload(session, msg).await?;
    publisher.put(payload).await.map_err(ProtoError::zenoh)
}

/// The session's shared-memory provider (zenoh's own pool), `None` where shared memory is
/// switched off in the zenoh configuration.
type Shm = std::sync::Arc<zenoh::shm::ShmProvider<zenoh::shm::PosixShmProviderBackend>>;

/// Interface data from this many bulk bytes on are encoded straight into shared memory.
const SHM_FROM: usize = 4096;

/// How long a message a low-latency link cannot carry inline waits for room in the pool
/// (the partner frees its buffers as it decodes them: normally microseconds).
const SHM_WAIT: Duration = Duration::from_secs(30);

/// The shared-memory side of sending interface data: the session's provider, taken on the
/// first large message (zenoh creates its pool lazily, so a process that sends none — the
/// coordinator of an explicit scheme — never maps it), and the count of data messages sent
/// and of those sent from shared memory.
#[derive(Default)]
struct ShmSend {
    provider: tokio::sync::OnceCell<Option<Shm>>,
    sent: DataCounts,
    /// The session asked for low-latency links ([`LinkConfig::lowlatency`]): a message larger
    /// than [`LOWLATENCY_INLINE_MAX`] must travel in shared memory.
    lowlatency: bool,
}

/// Interface data messages, and how many of them travelled in shared memory.
#[derive(Default)]
struct DataCounts([std::sync::atomic::AtomicU64; 2]);

impl DataCounts {
    fn add(&self, in_shm: bool) {
        use std::sync::atomic::Ordering::Relaxed;
        self.0[0].fetch_add(1, Relaxed);
        self.0[1].fetch_add(u64::from(in_shm), Relaxed);
    }

    fn get(&self) -> (u64, u64) {
        use std::sync::atomic::Ordering::Relaxed;
        (self.0[0].load(Relaxed), self.0[1].load(Relaxed))
    }
}

impl ShmSend {
    fn new(lowlatency: bool) -> ShmSend {
        ShmSend {
            lowlatency,
            ..Default::default()
        }
    }

    async fn provider(&self, session: &zenoh::Session) -> Option<&Shm> {
        self.provider
            .get_or_init(|| async { session.get_shm_provider().await })
            .await
            .as_ref()
    }

    /// The encoded message as a payload: an ordinary buffer, or — when it is too large for a
    /// low-latency link — encoded straight into a buffer of the pool ([`Self::alloc_required`]).
    async fn payload<M: Message>(
        &self,
        session: &zenoh::Session,
        msg: &M,
    ) -> Result<zenoh::bytes::ZBytes, ProtoError> {
        if self.lowlatency {
            let len = encoded_len(msg)?;
            if len > LOWLATENCY_INLINE_MAX {
                let mut buf = self.alloc_required(session, len, M::WHAT).await?;
                // the finiteness verdict is for interface data (put_data), not needed here
                encode_into_checked(msg, &mut buf)?;
                return Ok(buf.into());
            }
        }
        Ok(encode(msg)?.into())
    }

    /// A shared-memory buffer of `len` bytes for a message (`what`) that a low-latency link
    /// cannot carry inline: waits (up to [`SHM_WAIT`]) for the partner to free room in the
    /// pool rather than send it as a buffer, and fails with an error naming the message when
    /// there is no pool or no room.
    async fn alloc_required(
        &self,
        session: &zenoh::Session,
        len: usize,
        what: &str,
    ) -> Result<zenoh::shm::ZShmMut, ProtoError> {
        let advice = "this host's links run zenoh's low-latency transport, which carries at most \
                      64 kB per message outside shared memory; COSIM_LOWLATENCY=0 switches it off";
        let transport = |reason: String| ProtoError::Zenoh(format!("{what}: {reason} ({advice})"));
        if len > LOWLATENCY_POOL_BYTES {
            return Err(transport(format!(
                "{len} bytes do not fit the shared-memory pool of {LOWLATENCY_POOL_BYTES} bytes"
            )));
        }
        let provider = self
            .provider(session)
            .await
            .ok_or_else(|| transport(format!("{len} bytes and no shared-memory pool")))?;
        let alloc = provider
            .alloc(len)
            .with_policy::<zenoh::shm::BlockOn<zenoh::shm::Defragment<zenoh::shm::GarbageCollect>>>(
            );
        match tokio::time::timeout(SHM_WAIT, std::future::IntoFuture::into_future(alloc)).await {
            Ok(Ok(buf)) => Ok(buf),
            Ok(Err(e)) => Err(transport(format!(
                "{len} bytes not allocated in shared memory: {e:?}"
            ))),
            Err(_) => Err(transport(format!(
                "no room for {len} bytes in the shared-memory pool after {} s",
                SHM_WAIT.as_secs()
            ))),
        }
    }
}

/// Sends interface data. With a shared-memory provider the message is encoded straight into a
/// shared buffer: a peer on the same host maps it (no copy through the link), a peer on
/// another machine gets its bytes over the link as before. Without one, or when the pool is
/// full, the message goes as an ordinary buffer (which zenoh may still copy into shared memory
/// itself).
///
/// `check` refuses a message that must not leave (non-finite values of this node's own
/// solver); it runs before the message is sent unless the encoding into shared memory has
/// already checked every value on the way.
async fn put_data<M: Message>(
    publisher: &Publisher<'static>,
    msg: &M,
    session: &zenoh::Session,
    shm: &ShmSend,
    check: impl Fn() -> Result<(), ProtoError>,
) -> Result<(), ProtoError> {
    let provider = match msg.bulk_bytes() >= SHM_FROM {
        true => shm.provider(session).await,
        false => None,
    };
    if let Some(provider) = provider {
        let len = encoded_len(msg)?;
        // take back what the partners have released first, so that the pool's warm front is
        // reused instead of buffers further on, cold in every cache
        provider.garbage_collect();
        let buf = match provider
            .alloc(len)
            .with_policy::<zenoh::shm::GarbageCollect>()
            .wait()
        {
            Ok(buf) => Some(buf),
            Err(e) if shm.lowlatency && len > LOWLATENCY_INLINE_MAX => {
                tracing::debug!("{} of {len} bytes waits for the pool ({e:?})", M::WHAT);
                Some(shm.alloc_required(session, len, M::WHAT).await?)
            }
            Err(e) => {
                tracing::debug!(
                    "{} of {len} bytes not in shared memory ({e:?}): sent as a buffer",
                    M::WHAT
                );
                None
            }
        };
        if let Some(mut buf) = buf {
            if !encode_into_checked(msg, &mut buf)? {
                check()?;
            }
            publisher.put(buf).await.map_err(ProtoError::zenoh)?;
            shm.sent.add(true);
            return Ok(());
        }
    }
    check()?;
    put(publisher, msg, session, shm).await?;
    shm.sent.add(false);
    Ok(())
}

/// Interface data: labelled with window and iteration.
pub trait Data: Message {
    fn data_label(&self) -> Label;
}

impl Data for InterfaceKinematics {
    fn data_label(&self) -> Label {
        self.label()
    }
}

impl Data for InterfaceForces {
    fn data_label(&self) -> Label {
        self.label()
    }
}

/// Name of a command as written on the wire (`type`).
pub fn command_name(c: &CommandBody) -> &'static str {
    match c {
        CommandBody::Init(_) => "init",
        CommandBody::Publish { .. } => "publish",
        CommandBody::AdvanceWindow(_) => "advance_window",
        CommandBody::Checkpoint { .. } => "checkpoint",
        CommandBody::Rollback { .. } => "rollback",
        CommandBody::Snapshot { .. } => "snapshot",
        CommandBody::Restore { .. } => "restore",
        CommandBody::Stop { .. } => "stop",
    }
}

/// A node (solver) in a run.
pub struct Participant {
    session: zenoh::Session,
    keys: Keys,
    node: String,
    /// Declared once the node is in the run (its first command, `init`, accepted), so that a
    /// node that arrives in a run already under way never shows up as one of its nodes.
    token: Option<LivelinessToken>,
    commands: Subscriber<FifoChannelHandler<Sample>>,
    coordinator_alive: Subscriber<FifoChannelHandler<Sample>>,
    status: Publisher<'static>,
    next_seq: u64,
    publishers: HashMap<String, Publisher<'static>>,
    subscribers: HashMap<String, Subscriber<FifoChannelHandler<Sample>>>,
    queryables: Vec<Queryable<()>>,
    /// Repeated until the first command arrives: a coordinator that started after this node
    /// (another machine) did not hear the first one.
    hello: Option<Hello>,
    /// Per used interface: the provider's last end position (start of the next predictive
    /// motion).
    motion_start: std::collections::BTreeMap<String, Vec<f64>>,
    /// Interfaces whose input comes from the coordinator: provided ones' forces
    /// (`relaxed_forces`), used ones' kinematics (`relaxed_kinematics`).
    relaxed: std::collections::BTreeSet<String>,
    /// Interface data messages received, and how many of them arrived in shared memory.
    received: DataCounts,
    shm: ShmSend,
    /// `advance_window` commands that arrived while the node waited for interface data (the
    /// coordinator announces windows ahead: PROTOCOL.md §6), served in order by
    /// [`Self::next_command`].
    queued: std::collections::VecDeque<CommandBody>,
    /// When this node last sent interface data: what it computes after that in a window is
    /// bookkeeping its partner does not wait for ([`Self::last_data_sent`]).
    last_data_sent: std::sync::Mutex<Option<std::time::Instant>>,
}

/// A node's part in an interface.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Owns the mesh, publishes kinematics, reads forces (a FEM node).
    Provider,
    /// Reads kinematics, moves the mesh, publishes forces (a DEM node).
    User,
}

impl Participant {
    /// Joins run `run_id` as `node`: opens the session, listens for commands, declares the
    /// node's liveliness token (once its first command arrives) and sends `hello`.
    pub async fn connect(
        link: &LinkConfig,
        run_id: &str,
        node: &str,
        mut hello: Hello,
    ) -> Result<Participant, ProtoError> {
        validate_name("node", node)?;
        // this participant queues the windows announced ahead (Self::read)
        if !hello
            .capabilities
            .iter()
            .any(|c| c == crate::CAPABILITY_QUEUED_COMMANDS)
        {
            hello
                .capabilities
                .push(crate::CAPABILITY_QUEUED_COMMANDS.to_string());
        }
        if node == COORDINATOR {
            return Err(ProtoError::Name {
                what: "node (reserved for the coordinator)",
                name: node.into(),
            });
        }
        let keys = Keys::new(run_id)?;
        let (session, lowlatency) = link.open_with_mode().await?;
        let commands = session
            .declare_subscriber(keys.command(node))
            .with(zenoh::handlers::FifoChannel::new(CONTROL_QUEUE))
            .await
            .map_err(ProtoError::zenoh)?;
        let status = session
            .declare_publisher(keys.status(node))
            .congestion_control(CongestionControl::Block)
            .express(true)
            .await
            .map_err(ProtoError::zenoh)?;
        let coordinator_alive = session
            .liveliness()
            .declare_subscriber(keys.alive(COORDINATOR))
            .with(zenoh::handlers::FifoChannel::new(CONTROL_QUEUE))
            .await
            .map_err(ProtoError::zenoh)?;
        let mut p = Participant {
            session,
            keys,
            node: node.to_string(),
            token: None,
            commands,
            coordinator_alive,
            status,
            next_seq: 0,
            publishers: HashMap::new(),
            subscribers: HashMap::new(),
            queryables: Vec::new(),
            hello: None,
            motion_start: Default::default(),
            relaxed: Default::default(),
            received: Default::default(),
            shm: ShmSend::new(lowlatency),
            queued: Default::default(),
            last_data_sent: Default::default(),
        };
        p.report(StatusBody::Hello(hello.clone())).await?;
        p.hello = Some(hello);
        Ok(p)
    }

    pub fn node(&self) -> &str {
        &self.node
    }

    pub fn run_id(&self) -> &str {
        self.keys.run_id()
    }

    /// The next command from the coordinator. Commands are numbered; a gap or repeat is a
    /// protocol error. `None` waits forever.
    pub async fn next_command(
        &mut self,
        timeout: Option<Duration>,
    ) -> Result<CommandBody, ProtoError> {
        if !self.queued.is_empty() {
            // a `stop` that came in meanwhile goes before the windows kept (the run is over:
            // computing them would only write outputs past its end)
            while let Ok(Some(sample)) = self.commands.try_recv() {
                match self.accept_command(&sample)? {
                    stop @ CommandBody::Stop { .. } => {
                        self.queued.clear();
                        return Ok(stop);
                    }
                    other => self.queued.push_back(other),
                }
            }
            if let Some(c) = self.queued.pop_front() {
                return Ok(c);
            }
        }
        let deadline = timeout.map(|t| tokio::time::Instant::now() + t);
        let sample = loop {
            let sleep = async {
                match deadline {
                    Some(d) => tokio::time::sleep_until(d).await,
                    None => std::future::pending().await,
                }
            };
            let repeat_hello = async {
                match self.hello {
                    Some(_) => tokio::time::sleep(Duration::from_millis(500)).await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                s = self.commands.recv_async() => break s.map_err(|_| ProtoError::Closed)?,
                a = self.coordinator_alive.recv_async() => {
                    let a = a.map_err(|_| ProtoError::Closed)?;
                    if a.kind() == SampleKind::Delete {
                        return Err(ProtoError::PeerLost {
                            node: COORDINATOR.into(),
                            context: format!("while node `{}` waited for its next command", self.node),
                        });
                    }
                }
                _ = repeat_hello => {
                    if let Some(h) = self.hello.clone() {
                        self.report(StatusBody::Hello(h)).await?;
                    }
                }
                _ = sleep => return Err(ProtoError::Timeout {
                    what: "a command from the coordinator".into(),
                    waited: timeout.unwrap_or_default(),
                }),
            }
        };
        self.accept_command(&sample)
    }

    fn accept_command(&mut self, sample: &Sample) -> Result<CommandBody, ProtoError> {
        let cmd: Command = decode(&payload(sample), self.keys.run_id())?;
        if self.next_seq == 0 && cmd.seq != 0 {
            return Err(ProtoError::LateJoin {
                run: self.keys.run_id().to_string(),
                node: self.node.clone(),
                seq: cmd.seq,
            });
        }
        self.hello = None;
        if self.token.is_none() {
            let token = self
                .session
                .liveliness()
                .declare_token(self.keys.alive(&self.node))
                .wait()
                .map_err(ProtoError::zenoh)?;
            self.token = Some(token);
        }
        if cmd.seq != self.next_seq {
            return Err(ProtoError::Invalid {
                what: "command",
                reason: format!(
                    "sequence number {} where {} was expected",
                    cmd.seq, self.next_seq
                ),
            });
        }
        self.next_seq += 1;
        Ok(cmd.body)
    }

    /// Sends a status message to the coordinator.
    pub async fn report(&self, body: StatusBody) -> Result<(), ProtoError> {
        put(
            &self.status,
            &Status::new(self.keys.run_id(), &self.node, body),
            &self.session,
            &self.shm,
        )
        .await
    }

    /// Declares what this node exchanges on the interfaces of the run that name it: as a
    /// provider it subscribes to the forces and publishes kinematics, as a user the other way
    /// round (surface data; whether the node can couple an interface's kind is its own check).
    /// Returns the interfaces this node takes part in, in the order given. Call before
    /// reporting `ready`.
    pub async fn open_interfaces(
        &mut self,
        interfaces: &[InterfaceDecl],
    ) -> Result<Vec<(InterfaceDecl, Side)>, ProtoError> {
        let mut mine = Vec::new();
        for decl in interfaces {
            let name = &decl.name;
            validate_name("interface", name)?;
            let side = if decl.provider == self.node {
                Side::Provider
            } else if decl.users.iter().any(|u| u == &self.node) {
                Side::User
            } else {
                continue;
            };
            let (read, write) = match side {
                // the concurrent implicit scheme: the coordinator's estimated kinematics
                Side::User if decl.relaxed_kinematics => {
                    self.relaxed.insert(name.clone());
                    (self.keys.relaxed_kinematics(name), self.keys.forces(name))
                }
                Side::User => (self.keys.kinematics(name), self.keys.forces(name)),
                // implicit schemes: the coordinator's accelerated forces, not the users'
                Side::Provider if decl.relaxed_forces => {
                    self.relaxed.insert(name.clone());
                    (self.keys.relaxed_forces(name), self.keys.kinematics(name))
                }
                Side::Provider => (self.keys.forces(name), self.keys.kinematics(name)),
            };
            let sub = self
                .session
                .declare_subscriber(read.clone())
                .with(zenoh::handlers::FifoChannel::new(DATA_QUEUE))
                .await
                .map_err(ProtoError::zenoh)?;
            self.subscribers.insert(read, sub);
            let publisher = declare_data_publisher(&self.session, write.clone()).await?;
            self.publishers.insert(write, publisher);
            mine.push((decl.clone(), side));
        }
        Ok(mine)
    }

    /// Waits until every data publisher has a matching subscriber (the peer node opened its
    /// side), so that the first window's data cannot be published into the void. A `stop`
    /// (the other node failed its start) or the coordinator's departure ends the wait at once.
    pub async fn wait_for_peers(&mut self, timeout: Duration) -> Result<(), ProtoError> {
        let what = "the other solver's subscribers";
        match self
            .unless_stopped(what, self.peers_matched(timeout))
            .await?
        {
            Ok(()) => Ok(()),
            Err(command) => Err(self.stopped_by(&command, what)),
        }
    }

    async fn peers_matched(&self, timeout: Duration) -> Result<(), ProtoError> {
        let start = Instant::now();
        for (key, publisher) in &self.publishers {
            loop {
                let status = publisher
                    .matching_status()
                    .await
                    .map_err(ProtoError::zenoh)?;
                if status.matching() {
                    break;
                }
                if start.elapsed() > timeout {
                    return Err(ProtoError::Timeout {
                        what: format!("a subscriber of `{key}` (the other solver)"),
                        waited: timeout,
                    });
                }
                tokio::time::sleep(Duration::from_millis(5)).await;
            }
        }
        Ok(())
    }

    /// FEM side: serve the interface mesh to whoever asks (the DEM node, the coordinator).
    pub async fn provide_mesh(&mut self, mesh: &InterfaceMesh) -> Result<(), ProtoError> {
        mesh.validate()?;
        // every reply shares this one payload (on low-latency links a large mesh is placed in
        // shared memory once)
        let bytes = self.shm.payload(&self.session, mesh).await?;
        let key = self.keys.mesh(&mesh.interface);
        let reply_key = key.clone();
        let q = self
            .session
            .declare_queryable(key)
            .callback(move |query| {
                if let Err(e) = query.reply(reply_key.clone(), bytes.clone()).wait() {
                    tracing::warn!("could not reply with the interface mesh: {e}");
                }
            })
            .await
            .map_err(ProtoError::zenoh)?;
        self.queryables.push(q);
        Ok(())
    }

    /// User side: fetch the interface mesh, retrying until its provider serves it. A `stop`
    /// (the provider failed its start) or the coordinator's departure ends the wait at once.
    /// The mesh's positions are where the predictive motion of the first window starts.
    pub async fn read_mesh(
        &mut self,
        interface: &str,
        timeout: Duration,
    ) -> Result<InterfaceMesh, ProtoError> {
        let what = format!("the interface mesh `{interface}`");
        let fetch = fetch_mesh(&self.session, &self.keys, interface, timeout);
        match self.unless_stopped(&what, fetch).await? {
            Ok(mesh) => {
                self.motion_start
                    .insert(interface.to_string(), mesh.positions.0.clone());
                Ok(mesh)
            }
            Err(command) => Err(self.stopped_by(&command, &what)),
        }
    }

    /// The coupling memory of this node (each used interface's previous end position, where
    /// the next predictive motion starts), for snapshots: a restored node moves its meshes as
    /// the uninterrupted one would have.
    pub fn coupling_state(&self) -> Vec<u8> {
        rmp_serde::to_vec(&self.motion_start).expect("a map of float vectors encodes")
    }

    /// Puts back what [`Self::coupling_state`] returned.
    pub fn set_coupling_state(&mut self, bytes: &[u8]) -> Result<(), ProtoError> {
        self.motion_start = rmp_serde::from_slice(bytes).map_err(|e| ProtoError::Decode {
            what: "coupling state of a snapshot",
            reason: e.to_string(),
        })?;
        Ok(())
    }

    /// Runs `work` while watching the coordinator: `Err(command)` when a command arrives
    /// first (see [`Self::stopped_by`]), an error when the coordinator leaves.
    async fn unless_stopped<T>(
        &self,
        what: &str,
        work: impl std::future::Future<Output = Result<T, ProtoError>>,
    ) -> Result<Result<T, Sample>, ProtoError> {
        tokio::pin!(work);
        loop {
            tokio::select! {
                r = &mut work => return r.map(Ok),
                c = self.commands.recv_async() => {
                    return Ok(Err(c.map_err(|_| ProtoError::Closed)?));
                }
                a = self.coordinator_alive.recv_async() => {
                    let a = a.map_err(|_| ProtoError::Closed)?;
                    if a.kind() == SampleKind::Delete {
                        return Err(ProtoError::PeerLost {
                            node: COORDINATOR.into(),
                            context: format!("while waiting for {what}"),
                        });
                    }
                }
            }
        }
    }

    /// A command that arrived while this node waited for `what`: `stop` ends the wait
    /// ([`ProtoError::Stopped`], a clean exit), anything else is out of turn.
    fn stopped_by(&mut self, command: &Sample, what: &str) -> ProtoError {
        match self.accept_command(command) {
            Ok(CommandBody::Stop { reason }) => ProtoError::Stopped { reason },
            Ok(other) => ProtoError::Invalid {
                what: "command",
                reason: format!("received {} while waiting for {what}", command_name(&other)),
            },
            Err(e) => e,
        }
    }

    /// Publishes interface kinematics (FEM side). Non-finite values are never sent: they
    /// mean this node's solver diverged ([`ProtoError::Diverged`]).
    pub async fn write_kinematics(&self, k: &InterfaceKinematics) -> Result<(), ProtoError> {
        let check = || {
            for (field, a) in [
                ("positions", &k.positions),
                ("velocities", &k.velocities),
                ("accelerations", &k.accelerations),
            ] {
                own_finite(InterfaceKinematics::WHAT, &k.interface, k.window, field, a)?;
            }
            Ok(())
        };
        self.write(&self.keys.kinematics(&k.interface), k, check)
            .await
    }

    /// Publishes interface forces (DEM side); non-finite forces are refused as for kinematics.
    pub async fn write_forces(&self, f: &InterfaceForces) -> Result<(), ProtoError> {
        let check = || {
            own_finite(
                InterfaceForces::WHAT,
                &f.interface,
                f.window,
                "forces",
                &f.forces,
            )
        };
        self.write(&self.keys.forces(&f.interface), f, check).await
    }

    async fn write<M: Message>(
        &self,
        key: &str,
        msg: &M,
        check: impl Fn() -> Result<(), ProtoError>,
    ) -> Result<(), ProtoError> {
        let publisher = self
            .publishers
            .get(key)
            .ok_or_else(|| ProtoError::Invalid {
                what: M::WHAT,
                reason: format!("`{key}` was not opened by open_interfaces for this node"),
            })?;
        put_data(publisher, msg, &self.session, &self.shm, check).await?;
        *self
            .last_data_sent
            .lock()
            .unwrap_or_else(|e| e.into_inner()) = Some(std::time::Instant::now());
        Ok(())
    }

    /// When this node last sent interface data (forces or kinematics), if ever.
    pub fn last_data_sent(&self) -> Option<std::time::Instant> {
        *self
            .last_data_sent
            .lock()
            .unwrap_or_else(|e| e.into_inner())
    }

    /// Waits for and validates the kinematics labelled `label` (user side).
    pub async fn read_kinematics(
        &mut self,
        interface: &str,
        label: Label,
        nodes: usize,
        timeout: Duration,
    ) -> Result<InterfaceKinematics, ProtoError> {
        let key = if self.relaxed.contains(interface) {
            self.keys.relaxed_kinematics(interface)
        } else {
            self.keys.kinematics(interface)
        };
        let (k, finite): (InterfaceKinematics, bool) = self.read(&key, label, timeout).await?;
        if finite {
            k.validate_sizes(nodes, label)?;
        } else {
            k.validate(nodes, label)?;
        }
        Ok(k)
    }

    /// User side: waits for the kinematics labelled `label` and returns the mesh's motion for
    /// a window of length `dt` under `rule` ([`crate::motion`]: the schedule's maths is done
    /// here, not by the provider). Remembers the provider's end position for the next window.
    pub async fn read_motion(
        &mut self,
        interface: &str,
        label: Label,
        rule: MotionRule,
        dt: f64,
        nodes: usize,
        timeout: Duration,
    ) -> Result<crate::motion::MeshMotion, ProtoError> {
        let k = self
            .read_kinematics(interface, label, nodes, timeout)
            .await?;
        let start = self
            .motion_start
            .get(interface)
            .ok_or_else(|| ProtoError::Invalid {
                what: "interface kinematics",
                reason: format!("interface `{interface}` was read before its mesh"),
            })?;
        let motion = crate::motion::mesh_motion(rule, start, &k, dt);
        self.motion_start
            .insert(interface.to_string(), k.positions.0);
        Ok(motion)
    }

    /// Waits for and validates the forces labelled `label` (provider side): the users' own,
    /// or, where the interface says so, the coordinator's accelerated ones (implicit schemes).
    pub async fn read_forces(
        &mut self,
        interface: &str,
        label: Label,
        nodes: usize,
        timeout: Duration,
    ) -> Result<InterfaceForces, ProtoError> {
        let key = if self.relaxed.contains(interface) {
            self.keys.relaxed_forces(interface)
        } else {
            self.keys.forces(interface)
        };
        let (f, finite): (InterfaceForces, bool) = self.read(&key, label, timeout).await?;
        if finite {
            f.validate_sizes(nodes, label)?;
        } else {
            f.validate(nodes, label)?;
        }
        Ok(f)
    }

    /// Waits for data on `key`, watching the coordinator meanwhile: a `stop` command or the
    /// coordinator's disappearance ends the wait at once instead of at the timeout. Returns
    /// the message and whether its arrays are known to be finite ([`decode_finite`]).
    async fn read<M: Data>(
        &mut self,
        key: &str,
        label: Label,
        timeout: Duration,
    ) -> Result<(M, bool), ProtoError> {
        let what = format!("{} of {label} on `{key}`", M::WHAT);
        let sub = self
            .subscribers
            .get(key)
            .ok_or_else(|| ProtoError::Invalid {
                what: M::WHAT,
                reason: format!("`{key}` was not opened by open_interfaces for this node"),
            })?;
        let deadline = tokio::time::Instant::now() + timeout;
        let receive = async {
            loop {
                let sample = tokio::time::timeout_at(deadline, sub.recv_async())
                    .await
                    .map_err(|_| ProtoError::Timeout {
                        what: what.clone(),
                        waited: timeout,
                    })?
                    .map_err(|_| ProtoError::Closed)?;
                self.received.add(sample.payload().as_shm().is_some());
                match decode_finite::<M>(&payload(&sample), self.keys.run_id()) {
                    // not addressed to this run (a misconfigured or hostile publisher):
                    // refused and logged; the real message is still awaited
                    Err(e @ ProtoError::WrongRun { .. }) => {
                        tracing::warn!("refused on `{key}`: {e}")
                    }
                    // data of an iteration an implicit scheme abandoned (rolled back) before
                    // it was read: obsolete, skipped (PROTOCOL.md §4, Label)
                    Ok((m, _)) if m.data_label().iteration < label.iteration => {
                        tracing::debug!(
                            "skipped obsolete {} of {} on `{key}` (awaiting {label})",
                            M::WHAT,
                            m.data_label()
                        )
                    }
                    other => return other,
                }
            }
        };
        // commands that arrive meanwhile: windows announced ahead are kept for later, `stop`
        // (or anything out of turn) ends the wait
        let mut ahead: Vec<Sample> = Vec::new();
        let outcome = {
            tokio::pin!(receive);
            loop {
                match self.unless_stopped(&what, &mut receive).await? {
                    Ok(message) => break Ok(message),
                    Err(command) => {
                        let is_window = matches!(
                            decode::<Command>(&payload(&command), self.keys.run_id()),
                            Ok(Command {
                                body: CommandBody::AdvanceWindow(_),
                                ..
                            })
                        );
                        if !is_window {
                            break Err(command);
                        }
                        ahead.push(command);
                    }
                }
            }
        };
        // accepted in their order (sequence numbers), before the one that ended the wait
        for command in &ahead {
            let body = self.accept_command(command)?;
            self.queued.push_back(body);
        }
        outcome.map_err(|command| self.stopped_by(&command, &what))
    }

    /// Interface data messages this node has received, and how many of them arrived in
    /// shared memory (same host, zenoh's SHM transport) rather than as bytes over the link.
    pub fn data_received(&self) -> (u64, u64) {
        self.received.get()
    }

    /// Interface data messages this node has sent, and how many of them it encoded straight
    /// into shared memory (the rest went as ordinary buffers: small, or no shared memory).
    pub fn data_sent(&self) -> (u64, u64) {
        self.shm.sent.get()
    }

    /// Leaves the run: withdraws the liveliness token and closes the session.
    pub async fn finish(self) -> Result<(), ProtoError> {
        if let Some(token) = self.token {
            token.undeclare().await.map_err(ProtoError::zenoh)?;
        }
        self.session.close().await.map_err(ProtoError::zenoh)
    }
}

async fn fetch_mesh(
    session: &zenoh::Session,
    keys: &Keys,
    interface: &str,
    timeout: Duration,
) -> Result<InterfaceMesh, ProtoError> {
    validate_name("interface", interface)?;
    let key = keys.mesh(interface);
    let start = Instant::now();
    loop {
        let replies = session
            .get(key.clone())
            .timeout(Duration::from_millis(500))
            .await
            .map_err(ProtoError::zenoh)?;
        while let Ok(reply) = replies.recv_async().await {
            match reply.result() {
                Ok(sample) => {
                    let mesh: InterfaceMesh = decode(&payload(sample), keys.run_id())?;
                    if mesh.interface != interface {
                        return Err(ProtoError::Invalid {
                            what: "interface mesh",
                            reason: format!("asked for `{interface}`, got `{}`", mesh.interface),
                        });
                    }
                    mesh.validate()?;
                    return Ok(mesh);
                }
                Err(e) => tracing::warn!("mesh query error reply: {:?}", e.payload().to_bytes()),
            }
        }
        if start.elapsed() > timeout {
            return Err(ProtoError::Timeout {
                what: format!("the interface mesh `{interface}` (is the FEM node running?)"),
                waited: timeout,
            });
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// What the coordinator hears.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A status message from a node (key and message agree on the node name).
    Status(Status),
    /// A node's liveliness token appeared.
    Joined(String),
    /// A node's liveliness token disappeared: it died or its link was cut.
    Left(String),
    /// A message that failed decoding or validation; the run decides what to do.
    Rejected { key: String, error: String },
    /// A status message of another protocol version (from `node`, by its key).
    WrongVersion {
        node: Option<String>,
        got: u32,
        expected: u32,
    },
}

/// The coordinator's end of the wire: commands out, status and liveliness in.
pub struct CoordinatorLink {
    session: zenoh::Session,
    _token: LivelinessToken,
    keys: Keys,
    status: Subscriber<FifoChannelHandler<Sample>>,
    alive: Subscriber<FifoChannelHandler<Sample>>,
    commands: HashMap<String, (Publisher<'static>, u64)>,
    /// Publishers of accelerated forces, by key (implicit schemes).
    relaxed: HashMap<String, Publisher<'static>>,
    shm: ShmSend,
}

impl CoordinatorLink {
    pub async fn open(link: &LinkConfig, run_id: &str) -> Result<CoordinatorLink, ProtoError> {
        let keys = Keys::new(run_id)?;
        let (session, lowlatency) = link.open_with_mode().await?;
        let status = session
            .declare_subscriber(keys.status_all())
            .with(zenoh::handlers::FifoChannel::new(CONTROL_QUEUE))
            .await
            .map_err(ProtoError::zenoh)?;
        let alive = session
            .liveliness()
            .declare_subscriber(keys.alive_all())
            .history(true)
            .with(zenoh::handlers::FifoChannel::new(CONTROL_QUEUE))
            .await
            .map_err(ProtoError::zenoh)?;
        let token = session
            .liveliness()
            .declare_token(keys.alive(COORDINATOR))
            .await
            .map_err(ProtoError::zenoh)?;
        Ok(CoordinatorLink {
            shm: ShmSend::new(lowlatency),
            session,
            _token: token,
            keys,
            status,
            alive,
            commands: HashMap::new(),
            relaxed: HashMap::new(),
        })
    }

    pub fn keys(&self) -> &Keys {
        &self.keys
    }

    /// Whether this session asked for low-latency links ([`LinkConfig::lowlatency`]).
    pub fn lowlatency(&self) -> bool {
        self.shm.lowlatency
    }

    /// Sends a command to `node` (sequence numbers are kept per node).
    pub async fn send(&mut self, node: &str, body: CommandBody) -> Result<(), ProtoError> {
        validate_name("node", node)?;
        if !self.commands.contains_key(node) {
            let p = self
                .session
                .declare_publisher(self.keys.command(node))
                .congestion_control(CongestionControl::Block)
                .express(true)
                .await
                .map_err(ProtoError::zenoh)?;
            self.commands.insert(node.to_string(), (p, 0));
        }
        let (publisher, seq) = self.commands.get_mut(node).expect("inserted above");
        let cmd = Command::new(self.keys.run_id(), *seq, body);
        *seq += 1;
        put(publisher, &cmd, &self.session, &self.shm).await
    }

    /// The next event, or a timeout error naming `waiting_for`.
    pub async fn next_event(
        &self,
        timeout: Duration,
        waiting_for: &str,
    ) -> Result<Event, ProtoError> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            tokio::select! {
                s = self.status.recv_async() => {
                    let sample = s.map_err(|_| ProtoError::Closed)?;
                    let key = sample.key_expr().as_str().to_string();
                    return Ok(match decode::<Status>(&payload(&sample), self.keys.run_id()) {
                        Ok(st) if self.keys.node_of(&key).as_deref() == Some(st.node.as_str()) => Event::Status(st),
                        Ok(st) => Event::Rejected { key, error: format!("status claims node `{}` on another node's key", st.node) },
                        Err(ProtoError::Version { got, expected, .. }) => Event::WrongVersion { node: self.keys.node_of(&key), got, expected },
                        Err(e) => Event::Rejected { key, error: e.to_string() },
                    });
                }
                a = self.alive.recv_async() => {
                    let sample = a.map_err(|_| ProtoError::Closed)?;
                    let key = sample.key_expr().as_str().to_string();
                    match self.keys.node_of(&key) {
                        // our own token
                        Some(node) if node == COORDINATOR => continue,
                        Some(node) if sample.kind() == SampleKind::Put => return Ok(Event::Joined(node)),
                        Some(node) => return Ok(Event::Left(node)),
                        None => return Ok(Event::Rejected { key, error: "liveliness token outside the run's names".into() }),
                    }
                }
                _ = tokio::time::sleep_until(deadline) => {
                    return Err(ProtoError::Timeout { what: waiting_for.to_string(), waited: timeout });
                }
            }
        }
    }

    /// Fetches an interface mesh (the coordinator keeps it to monitor mesh drift).
    pub async fn read_mesh(
        &self,
        interface: &str,
        timeout: Duration,
    ) -> Result<InterfaceMesh, ProtoError> {
        fetch_mesh(&self.session, &self.keys, interface, timeout).await
    }

    /// Subscribes to all interface data of the run (monitoring). Declare only after every
    /// node is ready, so that nodes' publishers wait for each other, not for the monitor.
    /// A ring buffer: a slow monitor loses old samples rather than slow the solvers down — but
    /// each sample it holds keeps its sender's shared-memory buffer, which a sender on a
    /// low-latency link waits for when its pool is full: drain it every window, as the
    /// coordinator does.
    pub async fn monitor(&self) -> Result<Monitor, ProtoError> {
        let sub = self
            .session
            .declare_subscriber(self.keys.iface_all())
            .with(zenoh::handlers::RingChannel::new(64))
            .await
            .map_err(ProtoError::zenoh)?;
        Ok(Monitor {
            sub,
            run_id: self.keys.run_id().to_string(),
        })
    }

    /// A reliable tap on every interface's forces (implicit schemes read each iteration's
    /// forces here). Declare it before the nodes start, so that it is in place before the first
    /// window's forces are published.
    pub async fn forces_tap(&self) -> Result<DataTap<InterfaceForces>, ProtoError> {
        self.tap(self.keys.forces_all()).await
    }

    /// A reliable tap on every interface's kinematics (the concurrent implicit scheme), as
    /// [`CoordinatorLink::forces_tap`].
    pub async fn kinematics_tap(&self) -> Result<DataTap<InterfaceKinematics>, ProtoError> {
        self.tap(self.keys.kinematics_all()).await
    }

    async fn tap<M: TapData>(&self, key: String) -> Result<DataTap<M>, ProtoError> {
        let sub = self
            .session
            .declare_subscriber(key)
            .with(zenoh::handlers::FifoChannel::new(1024))
            .await
            .map_err(ProtoError::zenoh)?;
        Ok(DataTap {
            sub,
            run_id: self.keys.run_id().to_string(),
            early: Vec::new(),
        })
    }

    /// Publishes accelerated forces for an interface's provider (implicit schemes); the first
    /// time waits (up to `timeout`) until the provider listens.
    pub async fn publish_relaxed(
        &mut self,
        f: &InterfaceForces,
        timeout: Duration,
    ) -> Result<(), ProtoError> {
        let key = self.keys.relaxed_forces(&f.interface);
        self.publish_estimate(key, &f.interface, "provider", f, timeout)
            .await
    }

    /// Publishes estimated kinematics for an interface's users (the concurrent implicit
    /// scheme); the first time waits (up to `timeout`) until they listen.
    pub async fn publish_relaxed_kinematics(
        &mut self,
        k: &InterfaceKinematics,
        timeout: Duration,
    ) -> Result<(), ProtoError> {
        let key = self.keys.relaxed_kinematics(&k.interface);
        self.publish_estimate(key, &k.interface, "users", k, timeout)
            .await
    }

    async fn publish_estimate<M: Message>(
        &mut self,
        key: String,
        interface: &str,
        whom: &str,
        msg: &M,
        timeout: Duration,
    ) -> Result<(), ProtoError> {
        if !self.relaxed.contains_key(&key) {
            let p = declare_data_publisher(&self.session, key.clone()).await?;
            let start = Instant::now();
            while !p
                .matching_status()
                .await
                .map_err(ProtoError::zenoh)?
                .matching()
            {
                if start.elapsed() > timeout {
                    return Err(ProtoError::Timeout {
                        what: format!("the {whom} of interface `{interface}` to listen on `{key}`"),
                        waited: timeout,
                    });
                }
                tokio::time::sleep(Duration::from_millis(5)).await;
            }
            self.relaxed.insert(key.clone(), p);
        }
        put_data(
            &self.relaxed[&key],
            msg,
            &self.session,
            &self.shm,
            || Ok(()),
        )
        .await
    }

    pub async fn close(self) -> Result<(), ProtoError> {
        self.session.close().await.map_err(ProtoError::zenoh)
    }
}

/// Interface data the coordinator taps: its interface and its check.
pub trait TapData: Data {
    fn interface(&self) -> &str;
    fn check(&self, nodes: usize, label: Label) -> Result<(), ProtoError>;
}

impl TapData for InterfaceForces {
    fn interface(&self) -> &str {
        &self.interface
    }
    fn check(&self, nodes: usize, label: Label) -> Result<(), ProtoError> {
        self.validate(nodes, label)
    }
}

impl TapData for InterfaceKinematics {
    fn interface(&self) -> &str {
        &self.interface
    }
    fn check(&self, nodes: usize, label: Label) -> Result<(), ProtoError> {
        self.validate(nodes, label)
    }
}

/// The coordinator's reliable tap on the users' forces or the providers' kinematics
/// (implicit schemes).
pub struct DataTap<M> {
    sub: Subscriber<FifoChannelHandler<Sample>>,
    run_id: String,
    /// Messages that arrived before they were asked for (another interface's, or later).
    early: Vec<M>,
}

impl<M: TapData> DataTap<M> {
    /// The data of `interface` labelled `label`, validated for `nodes` nodes. Data of an
    /// earlier label is dropped (an explicit window's, or an abandoned iteration's); data of
    /// another interface or a later label is kept for its turn.
    pub async fn read(
        &mut self,
        interface: &str,
        label: Label,
        nodes: usize,
        timeout: Duration,
    ) -> Result<M, ProtoError> {
        self.early
            .retain(|f| f.interface() != interface || f.data_label() >= label);
        if let Some(i) = self
            .early
            .iter()
            .position(|f| f.interface() == interface && f.data_label() == label)
        {
            let f = self.early.remove(i);
            f.check(nodes, label)?;
            return Ok(f);
        }
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let sample = tokio::time::timeout_at(deadline, self.sub.recv_async())
                .await
                .map_err(|_| ProtoError::Timeout {
                    what: format!("{} of {label} on `{interface}`", M::WHAT),
                    waited: timeout,
                })?
                .map_err(|_| ProtoError::Closed)?;
            let f: M = match decode(&payload(&sample), &self.run_id) {
                Ok(f) => f,
                Err(e @ ProtoError::WrongRun { .. }) => {
                    tracing::warn!("refused {}: {e}", M::WHAT);
                    continue;
                }
                Err(e) => return Err(e),
            };
            if f.interface() == interface && f.data_label() == label {
                f.check(nodes, label)?;
                return Ok(f);
            }
            if f.interface() != interface || f.data_label() > label {
                self.early.push(f);
            }
        }
    }
}

/// This node's own output must be finite before it is published.
fn own_finite(
    what: &'static str,
    interface: &str,
    window: u64,
    field: &'static str,
    a: &F64Array,
) -> Result<(), ProtoError> {
    match a.first_non_finite() {
        None => Ok(()),
        Some((index, value)) => Err(ProtoError::Diverged {
            what,
            interface: interface.to_string(),
            window,
            field,
            index,
            value,
        }),
    }
}

/// Digest of one interface data message, for the coordinator's stability monitor.
#[derive(Debug, Clone, PartialEq)]
pub struct Digest {
    pub interface: String,
    pub window: u64,
    pub time: f64,
    /// `forces` or `kinematics`.
    pub kind: &'static str,
    /// Largest nodal force norm (forces) or largest nodal speed (kinematics).
    pub max_norm: f64,
    /// The interface node (in the interface's node order) where `max_norm` is, and with
    /// kinematics its position: what names the node when the monitor stops a run.
    pub max_node: usize,
    pub max_position: Option<[f64; 3]>,
    /// Sum of nodal forces (forces) or mean position (kinematics).
    pub total: [f64; 3],
    /// First non-finite value, if any.
    pub non_finite: Option<(&'static str, usize)>,
}

/// The largest norm of the 3-vectors in `a`, the (first) vector that has it, and their sum.
fn digest_arrays(a: &[f64]) -> (f64, usize, [f64; 3]) {
    let (mut max, mut at): (f64, usize) = (0.0, 0);
    let mut total = [0.0; 3];
    for (k, v) in a.chunks_exact(3).enumerate() {
        let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if norm > max {
            (max, at) = (norm, k);
        }
        for i in 0..3 {
            total[i] += v[i];
        }
    }
    (max, at, total)
}

/// The coordinator's tap on interface data.
pub struct Monitor {
    sub: Subscriber<zenoh::handlers::RingChannelHandler<Sample>>,
    run_id: String,
}

impl Monitor {
    /// Digests of everything that arrived since the last call (never blocks).
    pub fn drain(&self) -> Vec<Result<Digest, (String, ProtoError)>> {
        let mut out = Vec::new();
        while let Ok(Some(sample)) = self.sub.try_recv() {
            let key = sample.key_expr().as_str().to_string();
            let bytes = payload(&sample);
            let d = if key.ends_with("/forces") {
                decode::<InterfaceForces>(&bytes, &self.run_id).map(|f| {
                    let (max_norm, max_node, total) = digest_arrays(f.forces.as_slice());
                    Digest {
                        interface: f.interface.clone(),
                        window: f.window,
                        time: f.time,
                        kind: "forces",
                        max_norm,
                        max_node,
                        max_position: None,
                        total,
                        non_finite: f.forces.first_non_finite().map(|(i, _)| ("forces", i)),
                    }
                })
            } else if key.ends_with("/kinematics") {
                decode::<InterfaceKinematics>(&bytes, &self.run_id).map(|k| {
                    let (max_norm, max_node, _) = digest_arrays(k.velocities.as_slice());
                    let p = k.positions.as_slice();
                    // the mean position (no norms needed)
                    let mut sum = [0.0; 3];
                    for x in p.chunks_exact(3) {
                        (0..3).for_each(|i| sum[i] += x[i]);
                    }
                    let n = (p.len() / 3).max(1) as f64;
                    Digest {
                        interface: k.interface.clone(),
                        window: k.window,
                        time: k.time,
                        kind: "kinematics",
                        max_norm,
                        max_node,
                        max_position: p
                            .get(3 * max_node..3 * max_node + 3)
                            .map(|x| [x[0], x[1], x[2]]),
                        total: sum.map(|s| s / n),
                        non_finite: k
                            .positions
                            .first_non_finite()
                            .map(|(i, _)| ("positions", i))
                            .or(k
                                .velocities
                                .first_non_finite()
                                .map(|(i, _)| ("velocities", i)))
                            .or(k
                                .accelerations
                                .first_non_finite()
                                .map(|(i, _)| ("accelerations", i))),
                    }
                })
            } else {
                continue;
            };
            out.push(d.map_err(|e| (key, e)));
        }
        out
    }
}
