"""The cosim wire protocol, version 2 (proto/PROTOCOL.md), for a Python node.

Only what an FEM node needs: MessagePack encoding of the messages it sends, decoding and
boundary validation of the messages it receives, the key expressions of a run. No zenoh here.
"""

import math
import re

import msgpack
import numpy as np

PROTOCOL_VERSION = 2
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

    def relaxed_forces(self, interface):
        return f"cosim/{self.run}/iface/{interface}/forces_relaxed"


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


def label_text(label):
    """`window 3 iteration 0`: a `Label` as errors and logs name it (always both parts)."""
    return f"window {label['window']} iteration {label['iteration']}"


def interface_kinematics(run_id, interface, label, time, positions, velocities, accelerations):
    """`InterfaceKinematics`: the provider's state P, V, A at `time`, labelled `label`
    ({window, iteration}: the window and iteration whose users read it)."""
    return pack({
        "version": PROTOCOL_VERSION,
        "run_id": run_id,
        "interface": interface,
        "window": int(label["window"]),
        "iteration": int(label["iteration"]),
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

class _U32:
    """Type marker: a MessagePack unsigned integer below 2³² (`u32`); plain `int` is `u64`."""

    __name__ = "u32"


U32 = _U32()
U64_MAX = 2 ** 64 - 1
U32_MAX = 2 ** 32 - 1


class _Label:
    """Type marker: a `Label`, the map {window: u64, iteration: u32} (unknown keys ignored)."""

    __name__ = "label {window, iteration}"


LABEL = _Label()

COMMAND_FIELDS = {
    "init": {"scene_path": str, "scene_toml": str, "table": str, "out_dir": str,
             "interfaces": list, "check_only": bool, "trace": bool},
    "advance_window": {"window": int, "iteration": U32, "t_start": float, "dt": float,
                       "motion": str, "input": (LABEL, None), "output": (LABEL, None),
                       "static_solve": bool},
    "publish": {"label": LABEL},
    "checkpoint": {"window": int},
    "rollback": {"window": int},
    "snapshot": {"window": int, "path": str},
    "restore": {"window": int, "path": str},
    "stop": {"reason": str},
}
MOTIONS = ("quadratic", "linear", "fixed")
INTERFACE_KINDS = ("surface", "volume")
INTERFACE_DECL_FIELDS = {"name": str, "kind": str, "provider": str, "users": list,
                         "force_averaging": bool}


def _check_type(what, field, value, kind):
    kinds = kind if isinstance(kind, tuple) else (kind,)
    for k in kinds:
        if k is None and value is None:
            return value
        if k is float and isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)  # integers are accepted where a float is expected
        if k in (int, U32) and isinstance(value, int) and not isinstance(value, bool):
            if value < 0:
                raise ProtocolError(f"{what}: `{field}` must be unsigned, got {value}")
            limit, name = (U32_MAX, "u32") if k is U32 else (U64_MAX, "u64")
            if value > limit:
                raise ProtocolError(f"{what}: `{field}` = {value} does not fit in {name}")
            return value
        if k is LABEL and isinstance(value, dict):
            return decode_label(what, field, value)
        if k in (str, bool, list) and isinstance(value, k):
            return value
    names = " or ".join("nil" if k is None else k.__name__ for k in kinds)
    raise ProtocolError(f"{what}: `{field}` must be {names}, got {type(value).__name__} {value!r}")


def decode_label(what, field, value):
    """A `Label` map {window: u64, iteration: u32}; returns a plain dict of the two."""
    if not isinstance(value, dict):
        raise ProtocolError(f"{what}: `{field}` must be a label {{window, iteration}}, "
                            f"got {type(value).__name__} {value!r}")
    label = {}
    for part, kind in (("window", int), ("iteration", U32)):
        if part not in value:
            raise ProtocolError(f"{what}: `{field}` has no `{part}` (a label is {{window, iteration}})")
        label[part] = _check_type(what, f"{field}.{part}", value[part], kind)
    return label


def decode_interface_decl(what, index, value):
    """One `InterfaceDecl` of `init.interfaces`: {name, kind, provider, users,
    force_averaging}; names are checked, `kind` must be `surface` or `volume`."""
    field = f"interfaces[{index}]"
    if not isinstance(value, dict):
        raise ProtocolError(f"{what}: `{field}` must be an interface declaration map "
                            f"{{name, kind, provider, users, force_averaging}}, "
                            f"got {type(value).__name__} {value!r}")
    decl = {}
    for key, kind in INTERFACE_DECL_FIELDS.items():
        if key not in value:
            raise ProtocolError(f"{what}: `{field}` has no `{key}`")
        decl[key] = _check_type(what, f"{field}.{key}", value[key], kind)
    check_name("interface", decl["name"])
    if decl["kind"] not in INTERFACE_KINDS:
        raise ProtocolError(f"{what}: `{field}.kind` is `{decl['kind']}`, "
                            f"expected one of {', '.join(INTERFACE_KINDS)}")
    for i, user in enumerate(decl["users"]):
        if not isinstance(user, str):
            raise ProtocolError(f"{what}: `{field}.users[{i}]` must be a string, got {user!r}")
    # optional (absent: false): the provider reads the coordinator's accelerated forces
    decl["relaxed_forces"] = _check_type(what, f"{field}.relaxed_forces",
                                         value.get("relaxed_forces", False), bool)
    return decl


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
        body["interfaces"] = [decode_interface_decl("command `init`", i, d)
                              for i, d in enumerate(body["interfaces"])]
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


def decode_forces(payload, run_id, interface, label, nodes):
    """`InterfaceForces` labelled `label` ({window, iteration}) for an interface of `nodes`
    nodes; refuses any other label, naming both the one it carries and the one awaited."""
    what = "interface forces"
    msg = decode(payload, what, run_id, {
        "interface": str, "window": int, "iteration": U32, "time": float, "forces": None,
        "averaged": bool, "samples": U32})
    if msg["interface"] != interface:
        raise ProtocolError(f"{what}: for interface `{msg['interface']}`, expected `{interface}`")
    got = {"window": msg["window"], "iteration": msg["iteration"]}
    if got != {"window": label["window"], "iteration": label["iteration"]}:
        raise ProtocolError(f"{what} on interface `{interface}`: carries {label_text(got)}, "
                            f"expected {label_text(label)}")
    if not math.isfinite(msg["time"]):
        raise ProtocolError(f"{what}: time is {msg['time']}")
    msg["forces"] = decode_f64array(what, "forces", msg["forces"], 3 * nodes)
    return msg
