#!/usr/bin/env python3
"""Plays the coordinator and the DEM against fem_node.py over zenoh on loopback and checks the
parts of PROTOCOL.md a coupled run does not reach: `snapshot`/`restore` continue bitwise,
`publish`, data of another run is ignored, another protocol version is refused with an `error`
naming both versions and a non-zero exit. Exits non-zero (AssertionError) on any mismatch.

    python3 examples/python-fem-node/protocol_check.py [scene.toml]
"""

import json
import os
import queue
import socket
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import msgpack  # noqa: E402
import numpy as np  # noqa: E402
import zenoh  # noqa: E402

import wire  # noqa: E402

RUN = "protocol-check"
DT = 1e-4


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def main():
    scene = sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE, "../../scenes/plate.toml")
    work = tempfile.mkdtemp(prefix="fem-node-check-")
    p0, p1 = free_port(), free_port()
    cfg = zenoh.Config()
    cfg.insert_json5("mode", '"peer"')
    cfg.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{p0}"]))
    cfg.insert_json5("connect/endpoints", "[]")
    cfg.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(cfg)
    keys = wire.Keys(RUN)
    status, kinematics = queue.Queue(), queue.Queue()
    subs = [
        session.declare_subscriber(keys.status("fem"), lambda s: status.put(msgpack.unpackb(s.payload.to_bytes()))),
        session.declare_subscriber(keys.kinematics("top"), lambda s: kinematics.put(msgpack.unpackb(s.payload.to_bytes()))),
    ]
    token = session.liveliness().declare_token(keys.alive("coordinator"))
    commands = session.declare_publisher(keys.command("fem"))
    forces = session.declare_publisher(keys.forces("top"))
    node = subprocess.Popen([sys.executable, os.path.join(HERE, "fem_node.py"), "--run-id", RUN,
                             "--node", "fem", "--listen", f"tcp/127.0.0.1:{p1}",
                             "--connect", f"tcp/127.0.0.1:{p0}"])
    seq = [0]

    def send(body):
        commands.put(msgpack.packb({"version": 1, "run_id": RUN, "seq": seq[0], "body": body}))
        seq[0] += 1

    def reply(expected):
        body = status.get(timeout=60)["body"]
        assert body["type"] == expected, f"expected `{expected}`, got {body}"
        return body

    try:
        reply("hello")
        with open(scene) as f:
            send({"type": "init", "scene_path": scene, "scene_toml": f.read(), "out_dir": work,
                  "interfaces": ["top"], "check_only": False, "trace": False})
        ready = reply("ready")
        assert ready["limits"]["dofs"] > 0 and ready["limits"]["critical_time_step"] > 0, ready
        mesh = msgpack.unpackb(next(iter(session.get(keys.mesh("top")))).ok.payload.to_bytes())
        n = len(mesh["node_ids"])
        x0 = np.frombuffer(mesh["positions"], "<f8")
        tri = np.array(mesh["triangles"]).reshape(-1, 3)
        x = x0.reshape(-1, 3)
        normals = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
        assert x0.size == 3 * n and tri.max() < n and (normals[:, 2] > 0).all(), \
            "top interface triangles must be counter-clockwise seen from above (outside)"
        rng = np.random.default_rng(1)
        loads = [rng.normal(size=3 * n) * (k + 1) for k in range(10)]

        def window(k, run_id=RUN):
            if run_id != RUN:  # a stray message of another run first: must be ignored
                forces.put(msgpack.packb({"version": 1, "run_id": run_id, "interface": "top",
                                          "window": k, "time": k * DT, "forces": wire.f64array(-loads[k]),
                                          "averaged": False, "substeps": 10}))
            forces.put(msgpack.packb({"version": 1, "run_id": RUN, "interface": "top", "window": k,
                                      "time": k * DT, "forces": wire.f64array(loads[k]),
                                      "averaged": False, "substeps": 10}))
            send({"type": "advance_window", "window": k, "t_start": k * DT, "dt": DT, "substeps": 10,
                  "motion": "quadratic", "force_averaging": False, "input_window": k,
                  "output_window": k + 1, "static_solve": False})
            done = reply("window_done")
            assert done["window"] == k and abs(done["t_end"] - (k + 1) * DT) < 1e-15, done
            m = kinematics.get(timeout=30)
            assert m["window"] == k + 1 and abs(m["time"] - (k + 1) * DT) < 1e-15, m
            return [np.frombuffer(m[f], "<f8").copy() for f in ("positions", "velocities", "accelerations")]

        for k in range(5):
            window(k)
        snap = os.path.join(work, "fem-5.snapshot")
        send({"type": "snapshot", "window": 5, "path": snap})
        assert reply("snapshot_done")["path"] == snap
        first = [window(k) for k in range(5, 10)]
        send({"type": "restore", "window": 5, "path": snap})
        assert reply("restored")["window"] == 5
        second = [window(k, run_id="another-run") for k in range(5, 10)]
        assert all((a == b).all() for fa, fb in zip(first, second) for a, b in zip(fa, fb)), \
            "the restored node must continue bitwise (and ignore another run's data)"
        assert np.abs(first[-1][0] - x0).max() > 1e-9, "the plate must move for this to mean anything"
        send({"type": "publish", "window": 10, "force_averaging": False})
        m = kinematics.get(timeout=30)
        assert m["window"] == 10 and np.array_equal(np.frombuffer(m["positions"], "<f8"), second[-1][0])

        forces.put(msgpack.packb({"version": 2, "run_id": RUN, "interface": "top", "window": 10}))
        send({"type": "advance_window", "window": 10, "t_start": 10 * DT, "dt": DT, "substeps": 10,
              "motion": "linear", "force_averaging": False, "input_window": 10,
              "output_window": 10, "static_solve": False})
        err = reply("error")
        assert err["code"] == "protocol" and "version 2" in err["message"] \
            and "version 1" in err["message"] and err["window"] == 10, err
        code = node.wait(timeout=30)
        assert code != 0, "a node that reported an error must exit non-zero"
        print("protocol check passed: snapshot/restore bitwise, publish, another run ignored, "
              f"version 2 refused ({err['message']}), exit code {code}")
    finally:
        if node.poll() is None:
            node.kill()
        for s in subs:
            s.undeclare()
        token.undeclare()
        session.close()


if __name__ == "__main__":
    main()
