#!/usr/bin/env python3
"""Plays the coordinator and the DEM against fem_node.py over zenoh on loopback (no Rust build
needed) and checks the parts of PROTOCOL.md (version 2) a coupled run does not reach:

- `hello` names the node's `kind`; `init` reads the table `init.table` (here the node's own id),
  serves the interface whose `provider` is the node and ignores the others, writes under
  `<out_dir>/<node id>/`;
- windows with labels {window, iteration}: forces carry `iteration` and `samples`, kinematics
  carry the label and are always the state at the end of the window, whatever `motion` says;
- `snapshot`/`restore` continue bitwise, `publish` with a label, data of another run ignored,
  the time series cut back after a restore;
- `checkpoint`/`rollback`: a repeated window continues bitwise from the kept state, the time
  series lose the rows written since, a rollback to another window or without a checkpoint is an
  `error` with code `protocol`;
- refusals: forces of another iteration (naming both labels), another protocol version (naming
  both versions), interface declarations a FEM node cannot serve and a missing table (`scene`);
  each with an `error` and a non-zero exit;
- `stop` while the node waits for forces: `stopped`, exit 0.

Exits non-zero (AssertionError) on any mismatch; prints "protocol check passed" at the end.

    python3 examples/python-fem-node/protocol_check.py [scene.toml]
"""

import json
import os
import queue
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import msgpack  # noqa: E402
import numpy as np  # noqa: E402
import zenoh  # noqa: E402

import wire  # noqa: E402

RUN = "protocol-check"
DT = 1e-4
VERSION = wire.PROTOCOL_VERSION
IFACE = "top"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def label(window, iteration=0):
    return {"window": window, "iteration": iteration}


def decl(name, provider, users=("dem",), kind="surface", force_averaging=False):
    return {"name": name, "kind": kind, "provider": provider, "users": list(users),
            "force_averaging": force_averaging}


def rename_table(scene_text, table):
    """The scene with its `[fem]` tables (`[fem]`, `[fem.x]`, `[[fem.x]]`) renamed `table`: a
    scene whose structure is named by its node's id."""
    text, n = re.subn(r"^(\s*\[\[?\s*)fem(\s*[.\]])", rf"\g<1>{table}\g<2>", scene_text, flags=re.M)
    assert n > 0, "the scene has no [fem] table to rename"
    return text


def wait_matching(publisher, what, timeout=30):
    deadline = time.monotonic() + timeout
    while not publisher.matching_status.matching:
        assert time.monotonic() < deadline, f"no subscriber of {what} after {timeout} s"
        time.sleep(0.01)


def probe_times(out):
    """Times of the rows of the node's probe time series, or None if it writes none."""
    path = os.path.join(out, "fem_probes.csv")
    if not os.path.exists(path):
        return None
    with open(path) as f:
        lines = f.read().splitlines()
    assert lines[0].startswith("time"), lines[0]
    return [float(line.split(",")[0]) for line in lines[1:]]


class Harness:
    """One fem_node.py process in a run of its own; this script is its coordinator (commands,
    status, `alive/coordinator`) and its DEM (kinematics subscriber, forces publisher)."""

    def __init__(self, session, p0, work, tag, node):
        self.run = f"{RUN}-{tag}"
        self.node = node
        self.keys = wire.Keys(self.run)
        self.status, self.kinematics = queue.Queue(), queue.Queue()
        unpack = lambda s: msgpack.unpackb(s.payload.to_bytes())  # noqa: E731
        self.subs = [
            session.declare_subscriber(self.keys.status(node), lambda s: self.status.put(unpack(s))),
            session.declare_subscriber(self.keys.kinematics(IFACE),
                                       lambda s: self.kinematics.put(unpack(s))),
        ]
        self.token = session.liveliness().declare_token(self.keys.alive("coordinator"))
        block = dict(congestion_control=zenoh.CongestionControl.BLOCK,
                     reliability=zenoh.Reliability.RELIABLE)
        self.commands = session.declare_publisher(self.keys.command(node), **block)
        self.forces = session.declare_publisher(self.keys.forces(IFACE), **block)
        self.log_path = os.path.join(work, "logs", f"{tag}.log")
        os.makedirs(os.path.dirname(self.log_path), exist_ok=True)
        self.log = open(self.log_path, "w")
        self.proc = subprocess.Popen(
            [sys.executable, os.path.join(HERE, "fem_node.py"), "--run-id", self.run,
             "--node", node, "--listen", f"tcp/127.0.0.1:{free_port()}",
             "--connect", f"tcp/127.0.0.1:{p0}"],
            stdout=self.log, stderr=subprocess.STDOUT)
        self.seq = 0

    def send(self, body):
        self.commands.put(msgpack.packb(
            {"version": VERSION, "run_id": self.run, "seq": self.seq, "body": body}))
        self.seq += 1

    def reply(self, expected, timeout=60):
        msg = self.status.get(timeout=timeout)
        assert msg["version"] == VERSION and msg["run_id"] == self.run and msg["node"] == self.node, msg
        body = msg["body"]
        assert body["type"] == expected, f"{self.node}: expected `{expected}`, got {body}"
        return body

    def hello(self):
        body = self.reply("hello")
        assert body["kind"] == "fem" and "role" not in body, body
        assert "python" in body["software"] and body["pid"] == self.proc.pid, body
        wait_matching(self.commands, f"`{self.keys.command(self.node)}`")
        return body

    def init(self, scene_path, scene_text, table, interfaces, out_dir):
        self.send({"type": "init", "scene_path": scene_path, "scene_toml": scene_text,
                   "table": table, "out_dir": out_dir, "interfaces": interfaces,
                   "check_only": False, "trace": False})

    def put_forces(self, lab, values, run_id=None, version=VERSION, samples=10):
        self.forces.put(msgpack.packb({
            "version": version, "run_id": run_id or self.run, "interface": IFACE,
            "window": lab["window"], "iteration": lab["iteration"], "time": lab["window"] * DT,
            "forces": wire.f64array(values), "averaged": True, "samples": samples}))

    def advance(self, window, iteration=0, input_=None, output=None, motion="quadratic"):
        self.send({"type": "advance_window", "window": window, "iteration": iteration,
                   "t_start": window * DT, "dt": DT, "motion": motion, "input": input_,
                   "output": output, "static_solve": False})

    def expect_error(self, code, *words, window="any"):
        err = self.reply("error")
        assert err["code"] == code, f"{self.node}: expected an error with code `{code}`, got {err}"
        for w in words:
            assert w in err["message"], f"`{w}` not in the error message: {err['message']}"
        if window != "any":
            assert err["window"] == window, err
        exit_code = self.proc.wait(timeout=30)
        assert exit_code != 0, "a node that reported an error must exit non-zero"
        return err

    def close(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        for s in self.subs:
            s.undeclare()
        self.token.undeclare()
        self.commands.undeclare()
        self.forces.undeclare()
        self.log.close()


def main():
    scene = os.path.abspath(sys.argv[1] if len(sys.argv) > 1
                            else os.path.join(HERE, "../../scenes/plate.toml"))
    with open(scene) as f:
        scene_text = f.read()
    work = tempfile.mkdtemp(prefix="fem-node-check-")
    p0 = free_port()
    cfg = zenoh.Config()
    cfg.insert_json5("mode", '"peer"')
    cfg.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{p0}"]))
    cfg.insert_json5("connect/endpoints", "[]")
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("scouting/gossip/enabled", "false")
    session = zenoh.open(cfg)
    harnesses = []

    def start(tag, node):
        h = Harness(session, p0, work, tag, node)
        harnesses.append(h)
        h.hello()
        return h

    notes = []
    passed = False
    try:
        # ---- the main node: id `plate_a`, its structure in the table [plate_a] ----------------
        node = "plate_a"
        h = start("main", node)
        h.init(scene, rename_table(scene_text, node), node,
               [decl("other", "plate_b"), decl(IFACE, node)], work)
        ready = h.reply("ready")
        assert ready["limits"]["dofs"] > 0 and ready["limits"]["critical_time_step"] > 0, ready
        assert not any(w.startswith("fem.") for w in ready["warnings"]), \
            f"warnings must name keys under [{node}]: {ready['warnings']}"
        out = os.path.join(work, node)
        assert os.path.isdir(out) and not os.path.exists(os.path.join(work, "fem")), \
            "the node writes under <out_dir>/<node id>"
        wait_matching(h.forces, f"`{h.keys.forces(IFACE)}`")
        mesh = msgpack.unpackb(next(iter(session.get(h.keys.mesh(IFACE)))).ok.payload.to_bytes())
        assert mesh["version"] == VERSION and mesh["interface"] == IFACE, mesh
        assert not list(session.get(h.keys.mesh("other"))), "the node serves only its interface"
        n = len(mesh["node_ids"])
        x0 = np.frombuffer(mesh["positions"], "<f8")
        tri = np.array(mesh["triangles"]).reshape(-1, 3)
        x = x0.reshape(-1, 3)
        normals = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
        assert x0.size == 3 * n and tri.max() < n and (normals[:, 2] > 0).all(), \
            "top interface triangles must be counter-clockwise seen from above (outside)"
        rng = np.random.default_rng(1)
        loads = [rng.normal(size=3 * n) * (k + 1) for k in range(12)]

        def window(k, iteration=0, run_id=None, motion="quadratic"):
            """Window k (just-in-time labels: forces k in, kinematics k+1 out) at `iteration`;
            returns the kinematics P, V, A."""
            lab = label(k, iteration)
            if run_id is not None:  # a stray message of another run first: must be ignored
                h.put_forces(lab, -loads[k], run_id=run_id)
            h.put_forces(lab, loads[k])
            h.advance(k, iteration, input_=lab, output=label(k + 1, iteration), motion=motion)
            done = h.reply("window_done")
            assert done["window"] == k and abs(done["t_end"] - (k + 1) * DT) < 1e-15, done
            m = h.kinematics.get(timeout=30)
            assert m["version"] == VERSION and m["window"] == k + 1 and m["iteration"] == iteration, m
            # always the end of the window (no predictive velocity at t_start any more)
            assert abs(m["time"] - done["t_end"]) < 1e-15, (m["time"], done)
            return [np.frombuffer(m[f], "<f8").copy() for f in ("positions", "velocities", "accelerations")]

        for k in range(5):
            window(k)
        snap = os.path.join(work, f"{node}-5.snapshot")
        h.send({"type": "snapshot", "window": 5, "path": snap})
        assert h.reply("snapshot_done")["path"] == snap
        first = [window(k, motion="linear") for k in range(5, 10)]
        h.send({"type": "restore", "window": 5, "path": snap})
        assert h.reply("restored")["window"] == 5
        second = [window(k, run_id="another-run", motion="linear") for k in range(5, 10)]
        assert all((a == b).all() for fa, fb in zip(first, second) for a, b in zip(fa, fb)), \
            "the restored node must continue bitwise (and ignore another run's data)"
        assert np.abs(first[-1][0] - x0).max() > 1e-9, "the plate must move for this to mean anything"
        times = probe_times(out)
        if times is not None:
            assert len(times) == 10 and all(b > a for a, b in zip(times, times[1:])), \
                f"after a restore the time series lose the rows written since: {times}"
        else:
            notes.append("the scene has no probes: the time-series cuts were not checked")

        h.send({"type": "publish", "label": label(10)})
        m = h.kinematics.get(timeout=30)
        assert m["window"] == 10 and m["iteration"] == 0 and abs(m["time"] - 10 * DT) < 1e-15, m
        assert np.array_equal(np.frombuffer(m["positions"], "<f8"), second[-1][0])

        # checkpoint / rollback: an implicit scheme repeats window 10
        h.send({"type": "checkpoint", "window": 10})
        it0 = window(10, iteration=0, motion="quadratic")
        h.send({"type": "rollback", "window": 10})
        # the same forces with `linear` motion: the same end state, bitwise (the node does no
        # schedule maths), which also shows the rollback put the whole state back
        it1 = window(10, iteration=1, motion="linear")
        assert all((a == b).all() for a, b in zip(it0, it1)), \
            "a repeated window after `rollback` must continue bitwise from the checkpoint"
        if times is not None:
            times = probe_times(out)
            assert len(times) == 11 and abs(times[-1] - 11 * DT) < 1e-12 and \
                all(b > a for a, b in zip(times, times[1:])), \
                f"after a rollback the time series lose the rows written since: {times}"
        h.send({"type": "rollback", "window": 10})
        it2 = window(10, iteration=2, motion="fixed")
        assert all((a == b).all() for a, b in zip(it0, it2)), \
            "the kept checkpoint must serve a second rollback unchanged"
        h.send({"type": "rollback", "window": 10})
        # a stale iteration's forces while iteration 3 is awaited: refused, naming both labels
        h.put_forces(label(10, 2), loads[10])
        h.advance(10, 3, input_=label(10, 3), output=label(11, 3))
        stale = h.expect_error("protocol", "window 10 iteration 2", "window 10 iteration 3",
                               window=10)

        # ---- node id `fem`, table [fem]: rollback to another window than the kept one --------
        h = start("rollback", "fem")
        h.init(scene, scene_text, "fem", [decl(IFACE, "fem")], work)
        h.reply("ready")
        assert os.path.isdir(os.path.join(work, "fem"))
        wait_matching(h.forces, f"`{h.keys.forces(IFACE)}`")
        h.put_forces(label(0), loads[0])
        h.advance(0, input_=label(0), output=label(1))
        h.reply("window_done")
        h.kinematics.get(timeout=30)
        h.send({"type": "checkpoint", "window": 1})
        h.send({"type": "rollback", "window": 0})
        h.expect_error("protocol", "rollback", "window 0", "window 1", window=0)

        # ---- rollback without a checkpoint ---------------------------------------------------
        h = start("no-checkpoint", "fem")
        h.send({"type": "rollback", "window": 3})
        h.expect_error("protocol", "window 3", "checkpoint", window=None)

        # ---- another protocol version --------------------------------------------------------
        h = start("version", "fem")
        h.init(scene, scene_text, "fem", [decl(IFACE, "fem")], work)
        h.reply("ready")
        wait_matching(h.forces, f"`{h.keys.forces(IFACE)}`")
        h.put_forces(label(0), loads[0], version=1)
        h.advance(0, input_=label(0), output=label(1), motion="linear")
        version = h.expect_error("protocol", "version 1", "version 2", window=0)

        # ---- stop while the node waits for forces --------------------------------------------
        h = start("stop", "fem")
        h.init(scene, scene_text, "fem", [decl(IFACE, "fem")], work)
        h.reply("ready")
        h.advance(0, input_=label(0), output=label(1))
        h.send({"type": "stop", "reason": "protocol check: stop while waiting"})
        stopped = h.reply("stopped")
        assert stopped["results"]["dofs"] > 0, stopped
        assert h.proc.wait(timeout=30) == 0, "a stop while waiting ends the node with exit 0"

        # ---- init refusals: code `scene` -----------------------------------------------------
        refusals = [
            ("two-provided", "fem", "fem", [decl("a", "fem"), decl("b", "fem")],
             ("`fem`", "provider of 2 interfaces", "`a`", "`b`")),
            ("only-user", "fem", "fem", [decl(IFACE, "plate_b", users=["dem", "fem"])],
             (f"`{IFACE}`", "as a user")),
            ("volume", "fem", "fem", [decl(IFACE, "fem", kind="volume")],
             (f"`{IFACE}`", "volume", "surfaces only")),
            ("no-table", "plate_c", "plate_c", [decl(IFACE, "plate_c")],
             ("no [plate_c] table",)),
        ]
        bad_scene = rename_table(scene_text, "plate_d") + "\n[plate_d.loads]\nx = 1\n"
        for tag, node, table, interfaces, words in refusals + [
                ("bad-key", "plate_d", "plate_d", [decl(IFACE, "plate_d")], ("plate_d.loads",))]:
            h = start(tag, node)
            h.init(scene, bad_scene if tag == "bad-key" else scene_text, table, interfaces, work)
            h.expect_error("scene", scene, *words, window=None)

        print("protocol check passed: labels with iterations, kinematics at the window end, "
              "snapshot/restore and checkpoint/rollback bitwise with time series cut back, publish, "
              "another run ignored, refused: a stale iteration "
              f"({stale['message']}), another version ({version['message']}), rollbacks to another "
              f"or no checkpoint, {len(refusals) + 1} init errors (scene); stop while waiting "
              "(exit 0)" + "".join(f"; note: {n}" for n in notes))
        passed = True
    except BaseException:
        for h in harnesses:
            with open(h.log_path) as f:
                text = f.read()
            print(f"---- log of node `{h.node}` in run `{h.run}` ({h.log_path}):\n{text}",
                  file=sys.stderr)
        print(f"the node's files are in {work}", file=sys.stderr)
        raise
    finally:
        for h in harnesses:
            h.close()
        session.close()
    if passed:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
