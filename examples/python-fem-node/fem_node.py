#!/usr/bin/env python3
"""An FEM node of a cosim run written in Python from proto/PROTOCOL.md alone: eclipse-zenoh for
the transport, msgpack for the encoding, scikit-fem for the mechanics (plate_model.py).

Started by the coordinator as `fem_node.py --run-id R --node fem --listen tcp/127.0.0.1:P
--connect tcp/127.0.0.1:Q ...` (PROTOCOL.md §7), or by hand with the arguments `cosim run`
prints for an `external = true` node.
"""

import argparse
import json
import logging
import os
import pickle
import queue
import re
import sys
import time
from collections import deque

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import numpy as np  # noqa: E402
import zenoh  # noqa: E402

import wire  # noqa: E402
from plate_model import PlateModel, SceneError, UnstableError, parse_fem_table  # noqa: E402
from wire import ProtocolError  # noqa: E402

SOFTWARE = "python-fem-node 0.2 (protocol 2; scikit-fem, eclipse-zenoh)"
COORDINATOR = "coordinator"
log = logging.getLogger("fem_node")
logging.getLogger("skfem").setLevel(logging.WARNING)


class NodeError(Exception):
    """An error reported to the coordinator as `status` `error` with `code`."""

    def __init__(self, code, message):
        super().__init__(message)
        self.code = code


class Stopped(Exception):
    """`stop` arrived while the node waited for interface data."""

    def __init__(self, reason):
        super().__init__(reason)
        self.reason = reason


def zenoh_config(args):
    """PROTOCOL.md §1: a peer on exactly the given endpoints, multicast and gossip scouting off,
    3 s lease (or the one the coordinator that started it gives in COSIM_LINK_LEASE_MS); or a
    client of a router configured by `--zenoh-config`."""
    if args.zenoh_config:
        config = zenoh.Config.from_file(args.zenoh_config)
    else:
        config = zenoh.Config()
    if not args.zenoh_config or args.mode == "client":
        config.insert_json5("mode", json.dumps(args.mode))
    if not args.zenoh_config or args.listen:
        # exactly these endpoints: an empty list means "listen nowhere", never zenoh's default
        # of every interface
        config.insert_json5("listen/endpoints", json.dumps(args.listen))
    if not args.zenoh_config or args.connect:
        config.insert_json5("connect/endpoints", json.dumps(args.connect))
    config.insert_json5("scouting/multicast/enabled", "false")
    if not args.zenoh_config:
        config.insert_json5("scouting/gossip/enabled", "false")
        lease = os.environ.get("COSIM_LINK_LEASE_MS", "3000").strip()
        if not re.fullmatch(r"[0-9]+", lease) or not 100 <= int(lease) <= 3_600_000:
            raise SystemExit(f"COSIM_LINK_LEASE_MS={lease}: give the links' lease in whole "
                             "milliseconds, 100 to 3600000")
        config.insert_json5("transport/link/tx/lease", lease)
        config.insert_json5("transport/link/tx/keep_alive", "4")
    return config


class Participant:
    """The node's end of the wire. zenoh callbacks only put events on one queue; the main
    thread takes them in order, so commands, interface data and the coordinator's liveliness
    are handled without locks."""

    def __init__(self, args):
        self.keys = wire.Keys(args.run_id)
        self.node = wire.check_name("node", args.node)
        if self.node == COORDINATOR:
            raise ProtocolError("node name `coordinator` is reserved")
        self.run_id = args.run_id
        self.events = queue.Queue()
        self.forces_queue = deque()  # forces that arrived before the node asked for them
        # advance_window commands that arrived while the node waited for forces: the
        # coordinator announces windows ahead to nodes that say `queued_commands` (PROTOCOL.md §6)
        self.commands_queue = deque()
        self.next_seq = 0
        self.publishers = {}
        self.entities = []
        self.session = zenoh.open(zenoh_config(args))
        # PROTOCOL.md §5.2: command subscriber, coordinator's liveliness, own token, hello
        self.entities.append(self.session.declare_subscriber(
            self.keys.command(self.node),
            lambda s: self.events.put(("cmd", s.payload.to_bytes()))))
        self.entities.append(self.session.liveliness().declare_subscriber(
            self.keys.alive(COORDINATOR), lambda s: self.events.put(("coordinator", s.kind))))
        self.token = self.session.liveliness().declare_token(self.keys.alive(self.node))
        self.status = self.session.declare_publisher(
            self.keys.status(self.node), congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE)

    def report(self, body):
        self.status.put(wire.status(self.run_id, self.node, body))

    def _accept_command(self, payload):
        seq, body = wire.decode_command(payload, self.run_id)
        if seq != self.next_seq:
            raise ProtocolError(f"command: sequence number {seq} where {self.next_seq} was expected")
        self.next_seq += 1
        return body

    def _event(self, timeout, what):
        try:
            kind, value = self.events.get(timeout=timeout)
        except queue.Empty:
            raise NodeError("timeout", f"waited {timeout:.0f} s for {what}") from None
        if kind == "coordinator" and value == zenoh.SampleKind.DELETE:
            raise NodeError("protocol", f"the coordinator left (its liveliness token is gone) "
                                        f"while node `{self.node}` waited for {what}")
        return kind, value

    def next_command(self):
        if self.commands_queue:
            # a `stop` that came in meanwhile goes before the windows kept
            while True:
                try:
                    kind, value = self.events.get_nowait()
                except queue.Empty:
                    break
                if kind == "cmd":
                    body = self._accept_command(value)
                    if body["type"] == "stop":
                        self.commands_queue.clear()
                        return body
                    self.commands_queue.append(body)
                elif kind == "forces":
                    self.forces_queue.append(value)
                elif kind == "coordinator" and value == zenoh.SampleKind.DELETE:
                    raise NodeError("protocol", f"the coordinator left (its liveliness token is gone) "
                                                f"while node `{self.node}` had windows to run")
            return self.commands_queue.popleft()
        while True:
            kind, value = self._event(None, "its next command")
            if kind == "cmd":
                return self._accept_command(value)
            if kind == "forces":
                self.forces_queue.append(value)

    def open_interface(self, name, mesh_bytes, relaxed=False):
        """FEM side of §5.3: subscribe to `forces` (or, with `relaxed_forces`, to the
        coordinator's `forces_relaxed`), declare the `kinematics` publisher (reliable,
        congestion control Block), serve `mesh`."""
        key = self.keys.relaxed_forces(name) if relaxed else self.keys.forces(name)
        self.entities.append(self.session.declare_subscriber(
            key, lambda s: self.events.put(("forces", s.payload.to_bytes()))))
        self.publishers[name] = self.session.declare_publisher(
            self.keys.kinematics(name), congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE)
        key = self.keys.mesh(name)

        def reply(query):
            try:
                query.reply(key, mesh_bytes)
            except Exception as e:  # a vanished querier must not kill the node
                log.warning("could not reply with the interface mesh: %s", e)
        self.entities.append(self.session.declare_queryable(key, reply))

    def wait_for_peers(self, timeout):
        """Until every data publisher has a matching subscriber (the DEM listens)."""
        start = time.monotonic()
        for name, publisher in self.publishers.items():
            # `.matching`: the MatchingStatus object itself is always truthy
            while not publisher.matching_status.matching:
                if time.monotonic() - start > timeout:
                    raise NodeError("timeout", f"no subscriber of `{self.keys.kinematics(name)}` "
                                               f"(the other solver) after {timeout:.0f} s")
                time.sleep(0.005)

    def write_kinematics(self, name, payload):
        self.publishers[name].put(payload)

    def read_forces(self, name, label, nodes, timeout):
        """The forces labelled `label` ({window, iteration}); watches commands meanwhile (`stop`
        ends the wait)."""
        what = f"interface forces of {wire.label_text(label)} on `{self.keys.forces(name)}`"
        deadline = time.monotonic() + timeout
        while True:
            while not self.forces_queue:
                kind, value = self._event(max(0.0, deadline - time.monotonic()), what)
                if kind == "forces":
                    self.forces_queue.append(value)
                elif kind == "cmd":
                    body = self._accept_command(value)
                    if body["type"] == "stop":
                        raise Stopped(body["reason"])
                    if body["type"] == "advance_window":
                        self.commands_queue.append(body)
                        continue
                    raise ProtocolError(f"received {body['type']} while waiting for {what}")
            try:
                return wire.decode_forces(self.forces_queue.popleft(), self.run_id, name, label, nodes)
            except wire.WrongRun as e:
                log.warning("ignored: %s", e)  # PROTOCOL.md §8: another run's data is not an error

    def finish(self):
        """Withdraws the liveliness token and closes the session."""
        try:
            self.token.undeclare()
        finally:
            self.session.close()


def write_atomically(path, data):
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    tmp = os.path.splitext(path)[0] + ".tmp"
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def truncate_time_series_after(out_dir, t):
    """After a restore or a rollback to time t: every CSV time series in out_dir (header
    starting with `time`) loses the rows after t, which the interrupted run wrote after the
    checkpoint and the resumed run (or the repeated window) writes again (as fem-node and
    dem-node do; within 1e-8 relative)."""
    if not os.path.isdir(out_dir):
        return
    limit = t + 1e-8 * abs(t)
    for name in sorted(os.listdir(out_dir)):
        path = os.path.join(out_dir, name)
        if not name.endswith(".csv"):
            continue
        with open(path) as f:
            lines = f.read().splitlines(keepends=True)
        if not lines or lines[0].split(",")[0].strip() != "time":
            continue
        kept = [lines[0]]
        for line in lines[1:]:
            try:
                time = float(line.split(",")[0])
            except ValueError:
                break
            if not line.endswith("\n") or time > limit:
                break
            kept.append(line)
        if len(kept) < len(lines):
            write_atomically(path, "".join(kept).encode())


class Trace:
    """Per-window interface traces (`init.trace`), in fem-node's CSV format."""

    def __init__(self):
        self.files = {}

    def row(self, path, header, prefix, values):
        if path not in self.files:
            self.files[path] = open(path, "w")
            self.files[path].write(header + "\n")
        f = self.files[path]
        f.write(",".join(list(prefix) + [repr(float(v)) for v in values]) + "\n")
        f.flush()


class FemNode:
    def __init__(self, participant, data_timeout):
        self.p = participant
        self.data_timeout = data_timeout
        self.model = None
        self.interface = None  # (name, nodes) of the interface this node provides
        self.out_dir = None
        self.kept = None  # (window, model state) of the last `checkpoint`
        self.trace = None
        self.sent_at = None
        self.compute_s = 0.0
        self.wait_s = 0.0
        self.window = None

    def _provided_interface(self, c):
        """The interface of `init.interfaces` this node provides (PROTOCOL.md §4 InterfaceDecl),
        or None: a FEM node provides at most one surface and uses none."""
        node, scene = self.p.node, c["scene_path"]
        provided = [d for d in c["interfaces"] if d["provider"] == node]
        used = [d for d in c["interfaces"] if d["provider"] != node and node in d["users"]]
        if len(provided) > 1:
            names = ", ".join(f"`{d['name']}`" for d in provided)
            raise SceneError(f"{scene}: the scene's interfaces name node `{node}` as the provider "
                             f"of {len(provided)} interfaces ({names}); a FEM node provides one "
                             "surface (give each structure its own node)")
        if used:
            d = used[0]
            raise SceneError(f"{scene}: interface `{d['name']}` names the FEM node `{node}` as a "
                             f"user (its provider is `{d['provider']}`); a FEM node provides its "
                             f"surface (set provider = \"{node}\")")
        if not provided:
            return None
        d = provided[0]
        if d["kind"] != "surface":
            raise SceneError(f"{scene}: interface `{d['name']}` is a {d['kind']} interface; the "
                             f"FEM node `{node}` provides surfaces only")
        return d

    def init(self, c):
        decl = self._provided_interface(c)
        cfg = parse_fem_table(c["scene_toml"], c["scene_path"], c["table"])
        model = PlateModel(cfg)
        self.out_dir = os.path.join(c["out_dir"], self.p.node)  # <out_dir>/<node id>
        try:
            os.makedirs(self.out_dir, exist_ok=True)
        except OSError as e:
            raise NodeError("io", f"creating {self.out_dir}: {e}") from None
        self.trace = Trace() if c["trace"] else None
        if decl is not None:
            name = decl["name"]
            mesh = wire.interface_mesh(self.p.run_id, name, model.node_ids(),
                                       model.interface_positions(), model.triangles)
            self.interface = (name, len(model.iface_nodes))
            self.p.open_interface(name, mesh, decl["relaxed_forces"])
            self.p.wait_for_peers(self.data_timeout)
        limits = {"dofs": model.n_dofs}
        crit = model.critical_time_step()
        if crit is not None:
            limits["critical_time_step"] = crit
        self.model = model
        log.info("model: %d dofs, %d interface nodes, %d triangles, critical time step %s",
                 model.n_dofs, len(model.iface_nodes), len(model.triangles) // 3, crit)
        return {"type": "ready", "limits": wire.floats(limits), "warnings": model.warnings}

    def _model(self):
        if self.model is None:
            raise ProtocolError("a window command came before `init`")
        return self.model

    def _publish(self, label, time_, kin):
        """Publishes the interface's state (P, V, A at `time_`) labelled `label`. How the
        users move their meshes from it (`motion`) is theirs to compute (PROTOCOL.md §4)."""
        if self.interface is None:
            return False
        name = self.interface[0]
        self.p.write_kinematics(name, wire.interface_kinematics(
            self.p.run_id, name, label, time_, *kin))
        return True

    def advance(self, w):
        model = self._model()
        t0 = time.monotonic()
        forces = None
        if w["input"] is not None and self.interface is not None:
            name, nodes = self.interface
            forces = self.p.read_forces(name, w["input"], nodes, self.data_timeout)
        wait_s = time.monotonic() - t0
        if forces is not None:
            if self.trace is not None:
                path = os.path.join(self.out_dir, f"trace_{forces['interface']}_received_forces.csv")
                self.trace.row(path, "window,averaged,fx,fy,fz",
                               [str(forces["window"]), str(forces["averaged"]).lower()],
                               forces["forces"].reshape(-1, 3).sum(axis=0))
            model.set_interface_forces(forces["forces"])
        if w["static_solve"]:
            model.solve_static()
        else:
            model.advance(w["dt"])
        t_end = model.time
        pos, vel, acc = model.interface_kinematics()
        self.sent_at = None
        if w["output"] is not None:
            # always the state at the end of the window, whatever `motion` says: the users
            # compute the predictive motion (`linear`) from it themselves (PROTOCOL.md §4);
            # first, so that the partner need not wait for the outputs below
            if self._publish(w["output"], t_end, (pos, vel, acc)):
                self.sent_at = time.monotonic()
        model.write_outputs(self.out_dir)
        if self.trace is not None and self.interface is not None:
            path = os.path.join(self.out_dir, f"trace_{self.interface[0]}_mesh.csv")
            self.trace.row(path, "window,t_end,positions...,velocities...,accelerations...",
                           [str(w["window"])], np.concatenate([[t_end], pos, vel, acc]))
        speed = float(np.linalg.norm(vel.reshape(-1, 3), axis=1).max()) if vel.size else 0.0
        return wait_s, t_end, {"max_interface_speed": speed}

    def serve(self):
        """Commands until `stop` (PROTOCOL.md §4)."""
        while True:
            c = self.p.next_command()
            kind = c["type"]
            if kind == "init":
                self.p.report(self.init(c))
            elif kind == "advance_window":
                self.window = c["window"]
                t = time.monotonic()
                try:
                    wait_s, t_end, monitor = self.advance(c)
                except Stopped as s:
                    log.info("stop while waiting for interface data: %s", s.reason)
                    self.p.report(self.stopped())
                    return
                end = time.monotonic()
                compute = max(0.0, end - t - wait_s)
                # the outputs written after the kinematics left: off the critical path
                after = min(compute, end - self.sent_at) if self.sent_at is not None else 0.0
                self.compute_s += compute
                self.wait_s += wait_s
                self.p.report({"type": "window_done", "window": c["window"], "t_end": float(t_end),
                               "compute_s": compute, "wait_s": wait_s,
                               "monitor": wire.floats(monitor), "after_output_s": after})
            elif kind == "publish":
                model = self._model()
                self._publish(c["label"], model.time, model.interface_kinematics())
            elif kind == "checkpoint":
                # the start of a window an implicit scheme may repeat: a copy of the whole state
                # (the model's snapshot copies every array), kept in memory; no reply
                self.kept = (c["window"], self._model().snapshot())
            elif kind == "rollback":
                self.rollback(c["window"])
            elif kind == "snapshot":
                state = pickle.dumps(self._model().snapshot(), protocol=pickle.HIGHEST_PROTOCOL)
                try:
                    write_atomically(c["path"], state)
                except OSError as e:
                    raise NodeError("io", f"writing snapshot {c['path']}: {e}") from None
                self.p.report({"type": "snapshot_done", "window": c["window"], "path": c["path"]})
            elif kind == "restore":
                model = self._model()
                try:
                    with open(c["path"], "rb") as f:
                        state = pickle.load(f)
                    model.restore(state)
                except (OSError, pickle.UnpicklingError, ValueError, EOFError) as e:
                    raise NodeError("io", f"restoring the FEM state from {c['path']}: {e}") from None
                self._truncate_outputs()
                self.p.report({"type": "restored", "window": c["window"]})
            elif kind == "stop":
                log.info("stop: %s", c["reason"])
                self.p.report(self.stopped())
                return

    def rollback(self, window):
        """`rollback`: the state the last `checkpoint` kept, which must be of `window`, comes
        back; the time-series rows written since are cut, as after `restore`. No reply."""
        if self.kept is None:
            raise ProtocolError(f"`rollback` to window {window} without a `checkpoint` before it")
        kept_window, state = self.kept
        if kept_window != window:
            raise ProtocolError(f"`rollback` to window {window}, but the checkpoint kept is of "
                                f"window {kept_window}")
        model = self._model()
        model.restore(state)  # copies the arrays: the kept state serves further rollbacks
        self._truncate_outputs()

    def _truncate_outputs(self):
        """After a restore or a rollback: the CSV time series lose the rows after the model's
        time."""
        try:
            truncate_time_series_after(self.out_dir, self._model().time)
        except OSError as e:
            raise NodeError("io", f"shortening the time series in {self.out_dir}: {e}") from None

    def stopped(self):
        results = self.model.results() if self.model is not None else {}
        return {"type": "stopped", "results": wire.floats(results),
                "compute_s": self.compute_s, "wait_s": self.wait_s}


def error_code(e):
    if isinstance(e, NodeError):
        return e.code
    if isinstance(e, SceneError):
        return "scene"
    if isinstance(e, ProtocolError):
        return "protocol"
    if isinstance(e, UnstableError):
        return "unstable"
    if isinstance(e, OSError):
        return "io"
    return "internal"


def exit_with_coordinator():
    """Ends this process soon after the coordinator that started it is gone (it sets
    COSIM_COORDINATOR_PID, PROTOCOL.md §7), whatever the network says."""
    try:
        pid = int(os.environ.get("COSIM_COORDINATOR_PID", ""))
    except ValueError:
        return
    if pid <= 1:
        return
    direct_child = os.getppid() == pid

    def alive():
        if direct_child:
            return os.getppid() == pid
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            pass
        return True

    def watch():
        while alive():
            time.sleep(0.25)
        print(f"error: the coordinator (process {pid}) is gone: this node stops", file=sys.stderr)
        os._exit(3)

    import threading
    threading.Thread(target=watch, name="coordinator-watch", daemon=True).start()


def main(argv=None):
    ap = argparse.ArgumentParser(description="FEM solver node of a cosim run (Python, scikit-fem)")
    ap.add_argument("--run-id", required=True, help="run to join (the coordinator prints it)")
    ap.add_argument("--node", required=True,
                    help="id of this node in the run (`fem`, or the id the scene gives it)")
    ap.add_argument("--listen", action="append", default=[], help="endpoint to listen on (repeatable)")
    ap.add_argument("--connect", action="append", default=[], help="endpoint to connect to (repeatable)")
    ap.add_argument("--zenoh-config", help="zenoh configuration file (client of a router): see deploy/")
    ap.add_argument("--mode", default="peer", choices=["peer", "client"])
    ap.add_argument("--data-timeout", type=float, default=600.0,
                    help="longest wait for the other solver's interface data in one window (s)")
    args = ap.parse_args(argv)
    exit_with_coordinator()
    logging.basicConfig(level=os.environ.get("COSIM_PY_LOG", "INFO"), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(message)s")
    try:
        p = Participant(args)
    except Exception as e:
        print(f"error: node `{args.node}` in run `{args.run_id}`: cannot join: {e}", file=sys.stderr)
        return 1
    node = FemNode(p, max(args.data_timeout, 0.001))
    try:
        p.report({"type": "hello", "software": SOFTWARE, "kind": "fem",
                  "capabilities": ["snapshot", "static", "dynamic", "queued_commands"], "pid": os.getpid()})
        node.serve()
    except Exception as e:
        code = error_code(e)
        message = str(e) if code != "internal" else f"{type(e).__name__}: {e}"
        log.error("%s: %s", code, message, exc_info=code == "internal")
        try:
            p.report({"type": "error", "code": code, "message": message, "window": node.window})
            time.sleep(0.1)  # let the error reach the coordinator before the token goes
        except Exception as e2:
            log.error("could not report the error: %s", e2)
        try:
            p.finish()
        except Exception:
            pass
        return 1
    p.finish()
    return 0


if __name__ == "__main__":
    sys.exit(main())
