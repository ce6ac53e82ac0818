"""The FEM side of a cosim run in Python: linear elasticity on a generated box with
scikit-fem, static or Bossak–Newmark dynamics (REFERENCE A6). No zenoh here.

The node's table of the scene (`[fem]`, or `[<node id>]` when a scene has several structures) is
read with the meaning of fem-node/FEM.md's `[fem]`, restricted to what a generated box needs (see
README.md); anything else is refused with a `SceneError` naming the key.
"""

import math
import tomllib

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from scipy.spatial import cKDTree
from skfem import Basis, BilinearForm, ElementHex1, ElementHex2, ElementHexS2, MeshHex, asm

SNAPSHOT_FORMAT = 1
AXES = {"x": 0, "y": 1, "z": 2}


class SceneError(Exception):
    """The `[fem]` table is invalid or asks for something this node does not do (code `scene`)."""


class UnstableError(Exception):
    """The solution is not finite (code `unstable`)."""


# --------------------------------------------------------------------------------------------
# The [fem] table
# --------------------------------------------------------------------------------------------

def _table(value, key):
    if not isinstance(value, dict):
        raise SceneError(f"{key}: must be a table")
    return value


def _only(table, key, allowed):
    for k in table:
        if k not in allowed:
            raise SceneError(
                f"{key}.{k}: not supported by the Python FEM node (it reads {', '.join(allowed)})")


def _number(table, key, name, aliases=(), default=None):
    found = [n for n in (name, *aliases) if n in table]
    if len(found) > 1:
        raise SceneError(f"{key}.{found[1]}: given twice (also as `{found[0]}`)")
    if not found:
        if default is None:
            raise SceneError(f"{key}.{name}: missing")
        return default
    v = table[found[0]]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SceneError(f"{key}.{found[0]}: must be a number, got {v!r}")
    return float(v)


def _vector(value, key, length=3, kind=float):
    if not isinstance(value, list) or len(value) != length or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
        raise SceneError(f"{key}: must be an array of {length} numbers, got {value!r}")
    return [kind(x) for x in value]


def _selector(value, key):
    sel = _table(value, key)
    if len(sel) != 1:
        raise SceneError(f"{key}: must be exactly one of `plane`, `box`, `set`")
    (kind, spec), = sel.items()
    if kind == "plane":
        spec = _table(spec, f"{key}.plane")
        _only(spec, f"{key}.plane", ("axis", "value", "tol"))
        axis = spec.get("axis")
        if axis not in AXES:
            raise SceneError(f"{key}.plane.axis: must be \"x\", \"y\" or \"z\", got {axis!r}")
        tol = spec.get("tol")
        if tol is not None:
            tol = _number(spec, f"{key}.plane", "tol")
        return ("plane", AXES[axis], _number(spec, f"{key}.plane", "value"), tol)
    if kind == "box":
        spec = _table(spec, f"{key}.box")
        _only(spec, f"{key}.box", ("min", "max"))
        return ("box", _vector(spec.get("min"), f"{key}.box.min"),
                _vector(spec.get("max"), f"{key}.box.max"))
    if kind == "set":
        names = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax", "all")
        if spec not in names:
            raise SceneError(f"{key}.set: a generated box has the node sets {', '.join(names)}; got {spec!r}")
        return ("set", spec)
    raise SceneError(f"{key}.{kind}: not a selector (plane, box, set)")


def table_key(key, table):
    """`key` (a path under `fem`, as the checks below name it) under the node's own table:
    `fem.mesh.size` → `sleeper_left.mesh.size` when the node reads `[sleeper_left]`."""
    if table == "fem" or not key.startswith("fem"):
        return key
    rest = key[len("fem"):]
    if rest and (rest[0].isalnum() or rest[0] in "_-"):
        return key  # another word that merely starts with "fem"
    return table + rest


def parse_fem_table(scene_toml, scene_path, table="fem"):
    """Reads the node's table `[<table>]` of a scene (`[fem]`, or the node's id when a scene has
    several structures; the schema of `[fem]` either way); returns a plain dict. Errors name the
    scene file and the key under that table."""
    try:
        scene = tomllib.loads(scene_toml)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{scene_path}: {e}") from None
    if table not in scene:
        raise SceneError(f"{scene_path}: the scene has no [{table}] table")
    try:
        cfg = _parse(_table(scene[table], "fem"))
    except SceneError as e:
        raise SceneError(f"{scene_path}: {table_key(str(e), table)}") from None
    cfg["table"] = table
    return cfg


def _parse(fem):
    _only(fem, "fem", ("mesh", "material", "analysis", "supports", "interface", "probes", "output"))
    cfg = {}

    mesh = fem.get("mesh")
    if mesh is None:
        raise SceneError("fem.mesh: missing")
    if isinstance(mesh, str) or (isinstance(mesh, dict) and "file" in mesh):
        raise SceneError("fem.mesh: mesh files are not supported by the Python FEM node; "
                         "use a generated box `{ size, divisions, element }`")
    mesh = _table(mesh, "fem.mesh")
    _only(mesh, "fem.mesh", ("size", "origin", "divisions", "element_size", "element"))
    size = _vector(mesh.get("size"), "fem.mesh.size")
    if min(size) <= 0:
        raise SceneError(f"fem.mesh.size: must be positive, got {size}")
    origin = _vector(mesh.get("origin", [0.0, 0.0, 0.0]), "fem.mesh.origin")
    if ("divisions" in mesh) == ("element_size" in mesh):
        raise SceneError("fem.mesh: give exactly one of `divisions` and `element_size`")
    if "divisions" in mesh:
        div = _vector(mesh["divisions"], "fem.mesh.divisions", kind=int)
        if min(div) < 1 or any(d != x for d, x in zip(div, mesh["divisions"])):
            raise SceneError(f"fem.mesh.divisions: must be whole numbers ≥ 1, got {mesh['divisions']}")
    else:
        h = _number(mesh, "fem.mesh", "element_size")
        if h <= 0:
            raise SceneError(f"fem.mesh.element_size: must be positive, got {h}")
        div = [max(1, round(s / h)) for s in size]
    element = mesh.get("element", "hex8")
    if element not in ("hex8", "hex8i", "hex20"):
        raise SceneError(f"fem.mesh.element: `{element}` is not supported by the Python FEM node "
                         "(hex8, hex8i, hex20)")
    cfg["mesh"] = {"size": size, "origin": origin, "divisions": div, "element": element}

    mat = _table(fem.get("material"), "fem.material") if "material" in fem else None
    if mat is None:
        raise SceneError("fem.material: missing")
    _only(mat, "fem.material", ("youngs_modulus", "E", "poisson_ratio", "nu", "density", "rho"))
    e = _number(mat, "fem.material", "youngs_modulus", ("E",))
    nu = _number(mat, "fem.material", "poisson_ratio", ("nu",))
    rho = _number(mat, "fem.material", "density", ("rho",))
    if e <= 0:
        raise SceneError(f"fem.material.youngs_modulus: must be > 0, got {e}")
    if not -1.0 < nu < 0.5:
        raise SceneError(f"fem.material.poisson_ratio: must satisfy −1 < ν < 0.5, got {nu}")
    if rho <= 0:
        raise SceneError(f"fem.material.density: must be > 0, got {rho}")
    cfg["material"] = {"E": e, "nu": nu, "rho": rho}

    an = fem.get("analysis", "static")
    if isinstance(an, str):
        an = {"type": an}
    an = _table(an, "fem.analysis")
    _only(an, "fem.analysis", ("type", "alpha_b", "rayleigh_a", "rayleigh_b", "mass"))
    kind = an.get("type", "static")
    if kind not in ("static", "dynamic"):
        raise SceneError(f"fem.analysis.type: `{kind}` is not supported by the Python FEM node "
                         "(static, dynamic)")
    if kind == "static":
        _only(an, "fem.analysis", ("type",))
    alpha_b = _number(an, "fem.analysis", "alpha_b", default=-0.1)
    if not -1.0 / 3.0 <= alpha_b <= 0.0:
        raise SceneError(f"fem.analysis.alpha_b: must lie in [−1/3, 0], got {alpha_b}")
    if an.get("mass", "consistent") != "consistent":
        raise SceneError(f"fem.analysis.mass: only \"consistent\" is supported, got {an['mass']!r}")
    cfg["analysis"] = {
        "type": kind,
        "alpha_b": alpha_b,
        "rayleigh_a": _number(an, "fem.analysis", "rayleigh_a", default=0.0),
        "rayleigh_b": _number(an, "fem.analysis", "rayleigh_b", default=0.0),
    }

    supports = fem.get("supports", [])
    if not isinstance(supports, list):
        raise SceneError("fem.supports: must be an array of tables")
    cfg["supports"] = []
    for i, s in enumerate(supports):
        key = f"fem.supports[{i}]"
        s = _table(s, key)
        _only(s, key, ("on", "fix"))
        if "on" not in s:
            raise SceneError(f"{key}.on: missing")
        fix = s.get("fix", ["x", "y", "z"])
        if not isinstance(fix, list) or not fix or any(a not in AXES for a in fix):
            raise SceneError(f"{key}.fix: must be a non-empty array of \"x\", \"y\", \"z\", got {fix!r}")
        cfg["supports"].append((_selector(s["on"], f"{key}.on"), [AXES[a] for a in fix]))

    cfg["interface"] = None
    if "interface" in fem:
        it = _table(fem["interface"], "fem.interface")
        _only(it, "fem.interface", ("on",))
        if "on" in it:
            cfg["interface"] = _selector(it["on"], "fem.interface.on")

    probes = fem.get("probes", [])
    if not isinstance(probes, list):
        raise SceneError("fem.probes: must be an array of tables")
    cfg["probes"] = []
    for i, p in enumerate(probes):
        key = f"fem.probes[{i}]"
        p = _table(p, key)
        if "node" in p:
            raise SceneError(f"{key}.node: node ids of mesh files are not supported; use `point`")
        _only(p, key, ("name", "point"))
        name = p.get("name")
        if not isinstance(name, str) or not name:
            raise SceneError(f"{key}.name: must be a non-empty string")
        cfg["probes"].append((name, _vector(p.get("point"), f"{key}.point")))

    out = _table(fem.get("output", {}), "fem.output")
    _only(out, "fem.output", ("vtu_every", "csv"))
    if out.get("vtu_every", 0) != 0:
        raise SceneError("fem.output.vtu_every: the Python FEM node writes no VTU files; set 0")
    csv = out.get("csv", True)
    if not isinstance(csv, bool):
        raise SceneError(f"fem.output.csv: must be true or false, got {csv!r}")
    cfg["csv"] = csv
    cfg["vtu_given"] = "vtu_every" in out
    return cfg


# --------------------------------------------------------------------------------------------
# The model
# --------------------------------------------------------------------------------------------

# hex8i (incompatible modes) has no scikit-fem counterpart: triquadratic 27-node hexahedra on the
# same divisions represent the same pure bending exactly (quadratic through the thickness), as
# the incompatible modes do on rectangular elements.
ELEMENTS = {"hex8": ElementHex1, "hex8i": ElementHex2, "hex20": ElementHexS2}


def _face_triangles(corners, mids, centre):
    """Triangles of one quadrilateral face, corners counter-clockwise seen from outside;
    `mids[k]` is the node between corners k and k+1, `centre` the face node (or None)."""
    c, m = corners, mids
    if m is None:  # 4-node face: as fem-node's triangulate_face
        return [(c[0], c[1], c[2]), (c[0], c[2], c[3])]
    if centre is None:  # 8-node face: corner triangles, then the inner quad (fem-node)
        tris = [(c[k], m[k], m[(k + 3) % 4]) for k in range(4)]
        return tris + [(m[0], m[1], m[2]), (m[0], m[2], m[3])]
    # 9-node face: four sub-quads around the centre node, two triangles each
    tris = []
    for k in range(4):
        tris += [(c[k], m[k], centre), (m[k], c[(k + 1) % 4], centre)]
    return tris


def _sci(v):
    """`{:.9e}` as Rust writes it (fem-node's CSV): 1.234567890e-5, 0.000000000e0."""
    mantissa, exponent = f"{v:.9e}".split("e")
    return f"{mantissa}e{int(exponent)}"


class PlateModel:
    """Linear elastic box: K, M on the free dofs, Bossak–Newmark or static stepping."""

    def __init__(self, cfg):
        self.cfg = cfg
        self.table = cfg.get("table", "fem")  # the scene table the keys in messages are under
        self.warnings = []
        mc = cfg["mesh"]
        lo = np.array(mc["origin"])
        hi = lo + np.array(mc["size"])
        axes = [np.linspace(lo[k], hi[k], mc["divisions"][k] + 1) for k in range(3)]
        self.mesh = MeshHex.init_tensor(*axes)
        element = ELEMENTS[mc["element"]]()
        if mc["element"] == "hex8i":
            self.warnings.append(
                f"{self.table}.mesh.element = \"hex8i\": scikit-fem has no incompatible-mode "
                "hexahedra; using 27-node triquadratic hexahedra (ElementHex2) on the same "
                "divisions")
        if not cfg["vtu_given"]:
            self.warnings.append(
                f"{self.table}.output.vtu_every: the Python FEM node writes no VTU files")
        # 3×3×3 Gauss points integrate the mass and stiffness of these elements exactly on boxes
        order = 3 if mc["element"] == "hex8" else 5
        self.basis = Basis(self.mesh, element, intorder=order)
        # nodes = scalar dofs (vertices, and edge/face/interior nodes of quadratic elements);
        # vector dofs node-major: 3 n + c
        self.x = self.basis.doflocs.T.copy()
        n = self.x.shape[0]
        self.n_nodes = n
        self.n_dofs = 3 * n
        self.tree = cKDTree(self.x)
        self.diag = float(np.linalg.norm(hi - lo))

        mat = cfg["material"]
        lam = mat["E"] * mat["nu"] / ((1 + mat["nu"]) * (1 - 2 * mat["nu"]))
        mu = mat["E"] / (2 * (1 + mat["nu"]))
        self.rho = mat["rho"]
        K, M = self._assemble(lam, mu, self.rho)

        fixed = np.zeros(self.n_dofs, dtype=bool)
        for i, (sel, comps) in enumerate(cfg["supports"]):
            nodes = self.select_nodes(sel, f"{self.table}.supports[{i}].on")
            for c in comps:
                fixed[3 * nodes + c] = True
        self.free = np.flatnonzero(~fixed)
        self.K = K[self.free][:, self.free].tocsc()
        self.M = M[self.free][:, self.free].tocsc()
        # HRZ lumping (fem-node's lumped_mass): diagonal scaled to the element mass; every element
        # of a generated box has the same shape, so one factor serves the whole mesh.
        mdiag = M.diagonal()
        self.m_lumped = mdiag * (M.sum() / mdiag.sum())
        self.total_mass = M.sum() / 3.0

        self.iface_nodes, self.triangles = self._interface(cfg["interface"])
        self.probes = []
        for name, point in cfg["probes"]:
            _, node = self.tree.query(point)
            self.probes.append((name, int(node)))

        an = cfg["analysis"]
        self.dynamic = an["type"] == "dynamic"
        self.alpha_b, self.ra, self.rb = an["alpha_b"], an["rayleigh_a"], an["rayleigh_b"]
        self._k_lu = self._m_lu = None
        self._eff = None  # (dt, factor)
        self._crit = None
        z = np.zeros(self.n_dofs)
        self.st = {
            "format": SNAPSHOT_FORMAT, "n_dofs": self.n_dofs, "time": 0.0,
            "u": z.copy(), "v": z.copy(), "a": z.copy(),
            "interface_forces": np.zeros(3 * len(self.iface_nodes)),
            "accel_ready": False, "steps": 0, "windows": 0, "csv_started": False,
        }

    def _assemble(self, lam, mu, rho):
        """K and consistent M (node-major vector dofs) from scalar forms: the isotropic
        stiffness block (i, j) = λ ∫∂ᵢφ_a ∂ⱼφ_b + μ ∫∂ⱼφ_a ∂ᵢφ_b + μ δᵢⱼ ∫∇φ_a·∇φ_b
        (ten scalar forms are much faster to assemble than one vector form)."""
        b = self.basis
        d = [[asm(BilinearForm(lambda u, v, w, k=k, l=l: v.grad[k] * u.grad[l]), b)
              for l in range(3)] for k in range(3)]
        lap = d[0][0] + d[1][1] + d[2][2]
        blocks = [[lam * d[i][j] + mu * d[j][i] for j in range(3)] for i in range(3)]
        for i in range(3):
            blocks[i][i] = blocks[i][i] + mu * lap
        n = b.N
        perm = (np.arange(3)[None, :] * n + np.arange(n)[:, None]).ravel()
        K = sp.bmat(blocks).tocsr()[perm][:, perm]
        ms = asm(BilinearForm(lambda u, v, w: rho * u * v), b)
        M = sp.kron(ms, sp.identity(3)).tocsr()
        return K.tocsr(), M

    # ---- selection -----------------------------------------------------------------------

    def select_nodes(self, sel, what):
        x = self.x
        lo, hi = x.min(axis=0), x.max(axis=0)
        if sel[0] == "plane":
            _, k, value, tol = sel
            tol = 1e-6 * self.diag if tol is None else tol
            mask = np.abs(x[:, k] - value) <= tol
        elif sel[0] == "box":
            tol = 1e-9 * self.diag
            mask = np.all((x >= np.array(sel[1]) - tol) & (x <= np.array(sel[2]) + tol), axis=1)
        else:
            name = sel[1]
            tol = 1e-9 * self.diag
            if name == "all":
                mask = np.ones(len(x), dtype=bool)
            else:
                k = AXES[name[0]]
                v = lo[k] if name[1:] == "min" else hi[k]
                mask = np.abs(x[:, k] - v) <= tol
        nodes = np.flatnonzero(mask)
        if nodes.size == 0:
            raise SceneError(f"{what}: selects no nodes of the generated box")
        return nodes

    def _node_at(self, p):
        dist, n = self.tree.query(p)
        if dist > 1e-9 * self.diag:
            raise RuntimeError(f"no mesh node at {p} (nearest {dist:.3e} m away)")
        return int(n)

    def _interface(self, selector):
        """Exterior faces whose nodes are all selected, as triangles counter-clockwise seen
        from outside, over a compact node list sorted by mesh node index."""
        m = self.mesh
        selected = None
        if selector is not None:
            selected = np.zeros(self.n_nodes, dtype=bool)
            selected[self.select_nodes(selector, f"{self.table}.interface.on")] = True
        quadratic = self.cfg["mesh"]["element"] != "hex8"
        centre_node = self.cfg["mesh"]["element"] == "hex8i"
        tris = []
        for f in m.boundary_facets():
            p = m.p[:, m.facets[:, f]].T
            c = p.mean(axis=0)
            elem = m.f2t[0, f]
            outward = c - m.p[:, m.t[:, elem]].T.mean(axis=0)
            # face normal: the direction of least spread of its corners, pointing outwards
            normal = np.linalg.svd(p - c)[2][2]
            if normal @ outward < 0:
                normal = -normal
            e1 = p[0] - c
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(normal, e1)
            order = np.argsort(np.arctan2((p - c) @ e2, (p - c) @ e1))  # ccw about the normal
            p = p[order]
            corners = [self._node_at(q) for q in p]
            mids = [self._node_at(0.5 * (p[k] + p[(k + 1) % 4])) for k in range(4)] if quadratic else None
            centre = self._node_at(c) if centre_node else None
            nodes = corners + (mids or []) + ([centre] if centre is not None else [])
            if selected is not None and not selected[nodes].all():
                continue
            tris += _face_triangles(corners, mids, centre)
        if not tris:
            raise SceneError(
                f"{self.table}.interface.on: selects no exterior faces of the generated box")
        tris = np.array(tris, dtype=np.int64)
        nodes = np.unique(tris)
        local = np.full(self.n_nodes, -1, dtype=np.int64)
        local[nodes] = np.arange(len(nodes))
        return nodes, local[tris].ravel()

    # ---- the adapter-facing API -----------------------------------------------------------

    @property
    def time(self):
        return self.st["time"]

    def node_ids(self):
        """Mesh node ids (1-based, in node order), like the ids of fem-node's box generator."""
        return self.iface_nodes + 1

    def interface_positions(self):
        return self.x[self.iface_nodes].ravel()

    def set_interface_forces(self, forces):
        forces = np.asarray(forces, dtype=float)
        if forces.shape != (3 * len(self.iface_nodes),):
            raise ValueError(f"interface forces: {forces.size} values, expected {3 * len(self.iface_nodes)}")
        self.st["interface_forces"] = forces.copy()

    def interface_kinematics(self):
        idx = (3 * self.iface_nodes[:, None] + np.arange(3)).ravel()
        st = self.st
        return self.x[self.iface_nodes].ravel() + st["u"][idx], st["v"][idx].copy(), st["a"][idx].copy()

    def external_forces(self):
        """Interface forces scattered to the full dof vector (the only load of this node)."""
        f = np.zeros(self.n_dofs)
        idx = (3 * self.iface_nodes[:, None] + np.arange(3)).ravel()
        np.add.at(f, idx, self.st["interface_forces"])
        return f

    def advance(self, dt):
        """Static solve at t + dt (V = A = 0), or one Bossak step."""
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"time step {dt} must be positive")
        if self.dynamic:
            self._bossak_step(dt)
        else:
            self._static_solve()
            self.st["time"] += dt
        self.st["steps"] += 1

    def solve_static(self):
        """K u = F at the current time, whatever the analysis (one-way coupling)."""
        self._static_solve()

    def _set_free(self, name, values):
        full = np.zeros(self.n_dofs)
        full[self.free] = values
        self.st[name] = full

    def _check(self, x, what):
        if not np.all(np.isfinite(x)):
            raise UnstableError(f"{what} is not finite")

    def _static_solve(self):
        if self._k_lu is None:
            self._k_lu = sla.splu(self.K)
        u = self._k_lu.solve(self.external_forces()[self.free])
        self._check(u, "static displacement")
        self._set_free("u", u)
        self.st["v"] = np.zeros(self.n_dofs)
        self.st["a"] = np.zeros(self.n_dofs)
        self.st["accel_ready"] = False

    def _initial_acceleration(self):
        """M a₀ = F(t₀) − K (u₀ + b v₀) − a M v₀."""
        u, v = self.st["u"][self.free], self.st["v"][self.free]
        rhs = self.external_forces()[self.free] - self.K @ (u + self.rb * v) - self.ra * (self.M @ v)
        if self._m_lu is None:
            self._m_lu = sla.splu(self.M)
        self._set_free("a", self._m_lu.solve(rhs))
        self.st["accel_ready"] = True

    def _bossak_step(self, dt):
        """Wood–Bossak–Zienkiewicz (REFERENCE A6): M[(1−α_B) a_{n+1} + α_B a_n] + C v_{n+1}
        + K u_{n+1} = F_{n+1}, γ = ½ − α_B, β = (1 − α_B)²/4, C = a M + b K; the effective matrix
        (1−α_B) M + γΔt C + βΔt² K is factorised once per Δt."""
        ab = self.alpha_b
        gamma = 0.5 - ab
        beta = 0.25 * (1.0 - ab) ** 2
        if not self.st["accel_ready"]:
            self._initial_acceleration()
        if self._eff is None or self._eff[0] != dt:
            cm = (1.0 - ab) + gamma * dt * self.ra
            ck = gamma * dt * self.rb + beta * dt * dt
            self._eff = (dt, sla.splu((cm * self.M + ck * self.K).tocsc()))
        u, v, a = (self.st[k][self.free] for k in "uva")
        # predictors (Ullrich (2.85), (2.86)) without the a_{n+1} terms
        ut = u + dt * v + dt * dt * (0.5 - beta) * a
        vt = v + dt * (1.0 - gamma) * a
        rhs = (self.external_forces()[self.free]
               - self.M @ (ab * a + self.ra * vt) - self.K @ (self.rb * vt + ut))
        a1 = self._eff[1].solve(rhs)
        self._check(a1, "Bossak acceleration")
        self._set_free("u", ut + beta * dt * dt * a1)
        self._set_free("v", vt + gamma * dt * a1)
        self._set_free("a", a1)
        self.st["time"] += dt

    def critical_time_step(self):
        """Δt_crit = 2/ω_max (√(1+ξ²) − ξ) of central differences with the lumped mass, ω_max²
        the largest eigenvalue of M_L⁻¹K, ξ = a/(2ω) + bω/2 (fem-node's definition)."""
        if self._crit is None and self.free.size:
            s = 1.0 / np.sqrt(self.m_lumped[self.free])
            op = sp.diags(s) @ self.K @ sp.diags(s)
            lam = sla.eigsh(op, k=1, which="LA", tol=1e-8, return_eigenvectors=False)[0]
            w = math.sqrt(lam)
            xi = self.ra / (2 * w) + self.rb * w / 2
            self._crit = 2.0 / w * (math.sqrt(1 + xi * xi) - xi)
        return self._crit

    def probe(self, node):
        return self.st["u"][3 * node:3 * node + 3]

    def results(self):
        r = {
            "dofs": self.n_dofs,
            "free_dofs": self.free.size,
            "elements": self.mesh.t.shape[1],
            "time": self.st["time"],
        }
        for name, node in self.probes:
            for c, ax in enumerate(("ux", "uy", "uz")):
                r[f"probe.{name}.{ax}"] = self.st["u"][3 * node + c]
        total = self.st["interface_forces"].reshape(-1, 3).sum(axis=0)
        for c, ax in enumerate("xyz"):
            r[f"interface_force.{ax}"] = total[c]
        r["max_displacement"] = float(np.linalg.norm(self.st["u"].reshape(-1, 3), axis=1).max())
        if self._crit is not None:
            r["critical_time_step"] = self._crit
        return r

    def write_outputs(self, out_dir):
        """After each window: a row of probe displacements in `fem_probes.csv` (fem-node's
        format)."""
        self.st["windows"] += 1
        if not (self.cfg["csv"] and self.probes):
            return
        lines = []
        if not self.st["csv_started"]:
            lines.append("time" + "".join(
                f",probe.{n}.{c}" for n, _ in self.probes for c in ("ux", "uy", "uz")))
        row = _sci(self.st["time"]) + "".join(
            "," + _sci(self.st["u"][3 * node + c]) for _, node in self.probes for c in range(3))
        lines.append(row)
        mode = "a" if self.st["csv_started"] else "w"
        with open(f"{out_dir}/fem_probes.csv", mode) as f:
            f.write("\n".join(lines) + "\n")
        self.st["csv_started"] = True

    # ---- snapshot -------------------------------------------------------------------------

    def snapshot(self):
        return {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in self.st.items()}

    def restore(self, st):
        if not isinstance(st, dict) or st.get("format") != SNAPSHOT_FORMAT:
            raise ValueError(f"snapshot format {st.get('format') if isinstance(st, dict) else '?'} "
                             f"(expected {SNAPSHOT_FORMAT})")
        n = self.n_dofs
        ni = 3 * len(self.iface_nodes)
        if (st.get("n_dofs") != n or any(np.shape(st.get(k)) != (n,) for k in "uva")
                or np.shape(st.get("interface_forces")) != (ni,)):
            raise ValueError(f"snapshot has {st.get('n_dofs')} dofs, the model has {n}")
        self.st = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in st.items()}
