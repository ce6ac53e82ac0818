"""The cosim wire protocol, version 1 (proto/PROTOCOL.md), for a Python node.

Only what an FEM node needs: MessagePack encoding of the messages it sends, decoding and
boundary validation of the messages it receives, the key expressions of a run. No zenoh here.
"""

import math
import re

import msgpack
import numpy as np

PROTOCOL_VERSION = 1
NAME = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


class ProtocolError(Exception):
    """A message could not be decoded or failed validation (error code `protocol`)."""


class WrongRun(ProtocolError):
    """A message of another run: interface data of that kind is logged and ignored."""


def check_name(what, name):
    """Run ids, node and interface names: 1-64 characters of A-Z a-z 0-9 _ - (PROTOCOL.md §2)."""
    if not isinstance(name, str) or not NAME.match(name):
        raise ProtocolError(
            f"{what} `{name}` must be 1-64 characters of A-Z a-z 0-9 _ -")
    return name


class Keys:
    """Key expressions of one run (PROTOCOL.md §2)."""

    def __init__(self, run_id):
        self.run = check_name("run id", run_id)

    def command(self, node):
        return f"cosim/{self.run}/cmd/{node}"

    def status(self, node):
        return f"cosim/{self.run}/status/{node}"

    def alive(self, node):
        return f"cosim/{self.run}/alive/{node}"

    def mesh(self, interface):
        return f"cosim/{self.run}/iface/{interface}/mesh"

    def kinematics(self, interface):
        return f"cosim/{self.run}/iface/{interface}/kinematics"

    def forces(self, interface):
        return f"cosim/{self.run}/iface/{interface}/forces"


# --------------------------------------------------------------------------------------------
# Encoding
# --------------------------------------------------------------------------------------------

def f64array(values):
    """`f64array`: one MessagePack bin of little-endian IEEE-754 doubles, node-major xyz."""
    return np.ascontiguousarray(values, dtype="<f8").tobytes()


def pack(message):
    # use_bin_type: str → MessagePack str, bytes → bin; Python floats are written as float 64
    return msgpack.packb(message, use_bin_type=True)


def status(run_id, node, body):
    """A `Status` message on `status/<node>`; `body` holds `type` and the variant's fields."""
    return pack({"version": PROTOCOL_VERSION, "run_id": run_id, "node": node, "body": body})


def interface_mesh(run_id, interface, node_ids, positions, triangles):
    return pack({
        "version": PROTOCOL_VERSION,
        "run_id": run_id,
        "interface": interface,
        "node_ids": [int(i) for i in node_ids],
        "positions": f64array(positions),
        "triangles": [int(i) for i in triangles],
    })


def interface_kinematics(run_id, interface, window, time, positions, velocities, accelerations):
    return pack({
        "version": PROTOCOL_VERSION,
        "run_id": run_id,
        "interface": interface,
        "window": int(window),
        "time": float(time),
        "positions": f64array(positions),
        "velocities": f64array(velocities),
        "accelerations": f64array(accelerations),
    })


def floats(mapping):
    """`map`: string → f64."""
    return {str(k): float(v) for k, v in mapping.items()}


# --------------------------------------------------------------------------------------------
# Decoding with validation at the boundary
# --------------------------------------------------------------------------------------------

COMMAND_FIELDS = {
    "init": {"scene_path": str, "scene_toml": str, "out_dir": str, "interfaces": list,
             "check_only": bool, "trace": bool},
    "advance_window": {"window": int, "t_start": float, "dt": float, "substeps": int,
                       "motion": str, "force_averaging": bool, "input_window": (int, None),
                       "output_window": (int, None), "static_solve": bool},
    "publish": {"window": int, "force_averaging": bool},
    "snapshot": {"window": int, "path": str},
    "restore": {"window": int, "path": str},
    "stop": {"reason": str},
}
MOTIONS = ("quadratic", "linear", "fixed")


def _check_type(what, field, value, kind):
    kinds = kind if isinstance(kind, tuple) else (kind,)
    for k in kinds:
        if k is None and value is None:
            return value
        if k is float and isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)  # integers are accepted where a float is expected
        if k is int and isinstance(value, int) and not isinstance(value, bool):
            if value < 0:
                raise ProtocolError(f"{what}: `{field}` must be unsigned, got {value}")
            return value
        if k in (str, bool, list) and isinstance(value, k):
            return value
    names = " or ".join("nil" if k is None else k.__name__ for k in kinds)
    raise ProtocolError(f"{what}: `{field}` must be {names}, got {type(value).__name__} {value!r}")


def decode(payload, what, run_id, fields):
    """Decodes one message: a MessagePack map; `version` first, then the listed fields, then
    `run_id` (PROTOCOL.md §3). Unknown keys are ignored."""
    try:
        msg = msgpack.unpackb(bytes(payload), raw=False, strict_map_key=True)
    except Exception as e:  # msgpack raises several exception types
        raise ProtocolError(f"{what}: not MessagePack: {e}") from None
    if not isinstance(msg, dict) or "version" not in msg:
        raise ProtocolError(f"{what}: not a MessagePack map with a `version` field")
    if msg["version"] != PROTOCOL_VERSION:
        raise ProtocolError(
            f"{what}: the message speaks version {msg['version']}, "
            f"this node speaks version {PROTOCOL_VERSION}")
    for field, kind in {"run_id": str, **fields}.items():
        if field not in msg:
            raise ProtocolError(f"{what}: missing field `{field}`")
        if kind is not None:
            msg[field] = _check_type(what, field, msg[field], kind)
    if msg["run_id"] != run_id:
        raise WrongRun(f"{what}: belongs to run `{msg['run_id']}`, this is run `{run_id}`")
    return msg


def decode_command(payload, run_id):
    msg = decode(payload, "command", run_id, {"seq": int, "body": None})
    body = msg["body"]
    if not isinstance(body, dict) or not isinstance(body.get("type"), str):
        raise ProtocolError("command: `body` must be a map with a `type`")
    kind = body["type"]
    if kind not in COMMAND_FIELDS:
        raise ProtocolError(f"command: unknown type `{kind}`")
    for field, ty in COMMAND_FIELDS[kind].items():
        if field not in body:
            raise ProtocolError(f"command `{kind}`: missing field `{field}`")
        body[field] = _check_type(f"command `{kind}`", field, body[field], ty)
    if kind == "advance_window" and body["motion"] not in MOTIONS:
        raise ProtocolError(f"command `advance_window`: unknown motion `{body['motion']}`")
    if kind == "init":
        for name in body["interfaces"]:
            check_name("interface", name)
    return msg["seq"], body


def decode_f64array(what, field, value, length):
    """An `f64array` (bin of little-endian doubles, or an array of floats) of `length` values,
    all finite."""
    if isinstance(value, (bytes, bytearray)):
        if len(value) % 8:
            raise ProtocolError(f"{what}: `{field}` bin of {len(value)} bytes is not a multiple of 8")
        arr = np.frombuffer(value, dtype="<f8").astype(np.float64)
    elif isinstance(value, list):
        try:
            arr = np.array([float(v) for v in value], dtype=np.float64)
        except (TypeError, ValueError):
            raise ProtocolError(f"{what}: `{field}` is an array with non-numbers") from None
    else:
        raise ProtocolError(f"{what}: `{field}` must be a bin of doubles, got {type(value).__name__}")
    if arr.size != length:
        raise ProtocolError(
            f"{what}: `{field}` has {arr.size} values, expected {length} (3 per interface node)")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ProtocolError(f"{what}: `{field}` value {bad[0]} is {arr[bad[0]]}")
    return arr


def decode_forces(payload, run_id, interface, window, nodes):
    """`InterfaceForces` of `window` for an interface of `nodes` nodes; refuses any other."""
    what = "interface forces"
    msg = decode(payload, what, run_id, {
        "interface": str, "window": int, "time": float, "forces": None,
        "averaged": bool, "substeps": int})
    if msg["interface"] != interface:
        raise ProtocolError(f"{what}: for interface `{msg['interface']}`, expected `{interface}`")
    if msg["window"] != window:
        raise ProtocolError(f"{what}: carries window {msg['window']}, expected window {window}")
    if not math.isfinite(msg["time"]):
        raise ProtocolError(f"{what}: time is {msg['time']}")
    msg["forces"] = decode_f64array(what, "forces", msg["forces"], 3 * nodes)
    return msg
