//! Shells as a scene's structure (`fem::ShellModel` through `fem::build`): generated plates and
//! shell meshes from Gmsh and Abaqus files, supports with rotations, statics against beam
//! theory, Bossak dynamics against the modal frequency, the coupling's reference surfaces
//! (kinematics and the forces and moments they carry), snapshots, and refusals.

mod common;

use common::config;
use fem::ShellModel;
use std::path::Path;

/// A steel cantilever strip L × b × t clamped at x = 0, in the plane z = 0.
const L: f64 = 0.3;
const B: f64 = 0.05;
const T: f64 = 0.002;
const E: f64 = 210e9;
const RHO: f64 = 7800.0;

fn strip(extra: &str) -> String {
    format!(
        "[fem]\nmesh = {{ size = [{L}, {B}, 0.0], divisions = [24, 2, 0], element = \"mitc4\" }}\n\
         material = {{ youngs_modulus = {E}, poisson_ratio = 0.0, density = {RHO} }}\n\
         shell = {{ thickness = {T} }}\n\
         [[fem.supports]]\non = {{ set = \"xmin\" }}\n{extra}"
    )
}

fn shells(text: &str) -> ShellModel {
    ShellModel::from_config(&config(text)).unwrap_or_else(|e| panic!("shell model: {e}"))
}

fn tip_load(p: f64) -> String {
    format!("[[fem.loads]]\ntype = \"force\"\non = {{ set = \"xmax\" }}\ntotal = [0.0, 0.0, {p}]\n")
}

#[test]
fn cantilever_strip_matches_beam_theory_and_files_give_the_same_answer() {
    let p = -10.0;
    let text = strip(&format!(
        "{}[[fem.probes]]\nname = \"tip\"\npoint = [{L}, 0.0, 0.0]\n",
        tip_load(p)
    ));
    let mut m = shells(&text);
    m.solve_static().unwrap();
    let w = m.probe_displacement("tip").unwrap()[2];
    let i = B * T.powi(3) / 12.0;
    let exact = p * L.powi(3) / (3.0 * E * i);
    let err = (w - exact) / exact;
    eprintln!(
        "tip deflection {w:.6e} m, beam theory {exact:.6e} m: {:+.3} %",
        100.0 * err
    );
    assert!(err.abs() < 5e-3, "cantilever: {:+.3} %", 100.0 * err);
    // the bending stress at the root shell's centre: M c / I, tension on top, compression
    // below (the load points down); the shells' local e1 runs along x
    let stresses = m.surface_stresses();
    let x_c = L / 48.0;
    let sigma = -p * (L - x_c) * (T / 2.0) / i;
    let [top, bottom] = stresses[0];
    eprintln!(
        "root bending stress: top {:.4e}, bottom {:.4e}, M c / I {sigma:.4e} Pa",
        top[0], bottom[0]
    );
    assert!((top[0] / sigma - 1.0).abs() < 1e-2, "top {top:?}");
    assert!((bottom[0] / -sigma - 1.0).abs() < 1e-2, "bottom {bottom:?}");
    let vm = m
        .results()
        .into_iter()
        .find(|(k, _)| k == "max_von_mises")
        .unwrap()
        .1;
    assert!((vm / sigma - 1.0).abs() < 2e-2, "max von Mises {vm}");

    // the same strip from an Abaqus deck (S4R with its *SHELL SECTION) and a Gmsh file
    let dir = tempfile::tempdir().unwrap();
    let (nx, ny) = (24usize, 2usize);
    let id = |i: usize, j: usize| j * (nx + 1) + i + 1;
    let mut inp = String::from("*NODE\n");
    let mut msh_nodes = String::new();
    for j in 0..=ny {
        for i in 0..=nx {
            let (x, y) = (L * i as f64 / nx as f64, B * j as f64 / ny as f64);
            inp.push_str(&format!("{}, {x}, {y}, 0.0\n", id(i, j)));
            msh_nodes.push_str(&format!("{x} {y} 0\n"));
        }
    }
    inp.push_str("*ELEMENT, TYPE=S4R, ELSET=STRIP\n");
    let mut msh_elems = String::new();
    let mut e = 0;
    for j in 0..ny {
        for i in 0..nx {
            e += 1;
            let q = [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)];
            inp.push_str(&format!("{e}, {}, {}, {}, {}\n", q[0], q[1], q[2], q[3]));
            msh_elems.push_str(&format!("{e} {} {} {} {}\n", q[0], q[1], q[2], q[3]));
        }
    }
    inp.push_str(&format!(
        "*NSET, NSET=ROOT, GENERATE\n1, {}, {}\n*NSET, NSET=TIP, GENERATE\n{}, {}, {}\n\
         *SHELL SECTION, ELSET=STRIP, MATERIAL=STEEL\n{T}, 5\n",
        id(0, ny),
        nx + 1,
        nx + 1,
        id(nx, ny),
        nx + 1
    ));
    std::fs::write(dir.path().join("strip.inp"), &inp).unwrap();
    let n_nodes = (nx + 1) * (ny + 1);
    let msh = format!(
        "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 {n_nodes} 1 {n_nodes}\n2 1 0 {n_nodes}\n{}\n{msh_nodes}$EndNodes\n\
         $Elements\n1 {e} 1 {e}\n2 1 3 {e}\n{msh_elems}$EndElements\n",
        (1..=n_nodes).map(|k| k.to_string()).collect::<Vec<_>>().join("\n")
    );
    std::fs::write(dir.path().join("strip.msh"), msh).unwrap();
    let from_file = |mesh: &str, root: &str, tip: &str, thickness: &str| {
        let text = format!(
            "[fem]\nmesh = \"{mesh}\"\nmaterial = {{ youngs_modulus = {E}, poisson_ratio = 0.0, density = {RHO} }}\n\
             {thickness}[[fem.supports]]\non = {root}\n\
             [[fem.loads]]\ntype = \"force\"\non = {tip}\ntotal = [0.0, 0.0, {p}]\n\
             [[fem.probes]]\nname = \"tip\"\npoint = [{L}, 0.0, 0.0]\n"
        );
        let mut s =
            fem::build(&config(&text), dir.path()).unwrap_or_else(|e| panic!("{mesh}: {e}"));
        s.solve_static().unwrap();
        s.results()
            .into_iter()
            .find(|(k, _)| k == "probe.tip.uz")
            .unwrap()
            .1
    };
    let w_inp = from_file("strip.inp", "{ set = \"ROOT\" }", "{ set = \"TIP\" }", "");
    let plane = |x: f64| format!("{{ plane = {{ axis = \"x\", value = {x} }} }}");
    let w_msh = from_file(
        "strip.msh",
        &plane(0.0),
        &plane(L),
        &format!("shell = {{ thickness = {T} }}\n"),
    );
    eprintln!("Abaqus S4R deck {w_inp:.9e} m, Gmsh quadrangles {w_msh:.9e} m");
    assert!(
        ((w_inp - w) / w).abs() < 1e-10,
        "Abaqus deck: {w_inp} vs {w}"
    );
    assert!(((w_msh - w) / w).abs() < 1e-10, "Gmsh file: {w_msh} vs {w}");
}

#[test]
fn hinged_support_frees_the_rotations() {
    // a strip hinged (rotations free) at both ends under its own weight: 5/384 q L⁴ / EI at
    // midspan; clamped it would be 1/384
    let text = format!(
        "[fem]\nmesh = {{ size = [{L}, {B}, 0.0], divisions = [24, 2, 0], element = \"mitc4\" }}\n\
         material = {{ youngs_modulus = {E}, poisson_ratio = 0.0, density = {RHO} }}\n\
         shell = {{ thickness = {T} }}\n\
         [[fem.supports]]\non = {{ set = \"xmin\" }}\nrotations = [\"x\", \"z\"]\n\
         [[fem.supports]]\non = {{ set = \"xmax\" }}\nfix = [\"y\", \"z\"]\nrotations = [\"x\", \"z\"]\n\
         [[fem.loads]]\ntype = \"gravity\"\nacceleration = [0.0, 0.0, -9.81]\n\
         [[fem.probes]]\nname = \"mid\"\npoint = [{}, 0.0, 0.0]\n",
        L / 2.0
    );
    let mut m = shells(&text);
    m.solve_static().unwrap();
    let w = m.probe_displacement("mid").unwrap()[2];
    let q = -RHO * 9.81 * T * B;
    let exact = 5.0 * q * L.powi(4) / (384.0 * E * B * T.powi(3) / 12.0);
    let err = (w - exact) / exact;
    eprintln!(
        "hinged strip under gravity: {w:.6e} m vs {exact:.6e} m ({:+.3} %)",
        100.0 * err
    );
    assert!(err.abs() < 5e-3, "{:+.3} %", 100.0 * err);
}

#[test]
fn bossak_free_vibration_has_the_modal_period_and_conserves_energy() {
    let text = strip(
        "[fem.analysis]\ntype = \"dynamic\"\nalpha_b = 0.0\n\
         [[fem.probes]]\nname = \"tip\"\nnode = 25\n",
    );
    let mut m = shells(&text);
    // the first bending mode: beam theory f = 1.875² / 2π √(EI / (ρ A L⁴))
    let f_beam = 1.875104f64.powi(2) / (2.0 * std::f64::consts::PI)
        * (E * B * T.powi(3) / 12.0 / (RHO * B * T * L.powi(4))).sqrt();
    let f1 = m.lowest_frequency_hz().unwrap().unwrap();
    eprintln!("lowest frequency {f1:.4} Hz, beam theory {f_beam:.4} Hz");
    assert!(((f1 - f_beam) / f_beam).abs() < 5e-3);
    // start from the static shape under a tip load, released: period from zero crossings
    let mut s = shells(&strip(&tip_load(-1.0)));
    s.solve_static().unwrap();
    let u0 = s.displacements().to_vec();
    m.set_initial_conditions(&u0, &vec![0.0; u0.len()]).unwrap();
    let e0 = m.strain_energy();
    let period = 1.0 / f1;
    let dt = period / 200.0;
    let mut crossings = Vec::new();
    let mut last = m.probe_displacement("tip").unwrap()[2];
    let mut worst: f64 = 0.0;
    for k in 1..=700 {
        m.advance(dt).unwrap();
        let w = m.probe_displacement("tip").unwrap()[2];
        if last < 0.0 && w >= 0.0 {
            // upward crossing, linearly interpolated
            crossings.push((k as f64 - w / (w - last)) * dt);
        }
        last = w;
        let e = m.strain_energy() + m.kinetic_energy();
        worst = worst.max(((e - e0) / e0).abs());
    }
    let measured = crossings[1] - crossings[0];
    // trapezoidal rule (α_B = 0): the period lengthens by ≈ (ωΔt)²/12 = 0.08 %; the tip
    // load's shape also holds higher modes
    eprintln!(
        "period {measured:.6e} s vs 1/f₁ {period:.6e} s ({:+.3} %); energy drift {worst:.2e}",
        100.0 * (measured / period - 1.0)
    );
    assert!((measured / period - 1.0).abs() < 1e-2);
    assert!(worst < 1e-9, "energy drift {worst}");
}

#[test]
fn the_reference_surfaces_carry_forces_and_moments_of_the_dem() {
    let text = strip(
        "[fem.analysis]\ntype = \"dynamic\"\n[fem.interface]\non = { box = { min = [0.1, -1.0, -1.0], max = [0.3, 1.0, 1.0] } }\n",
    );
    let mut m = shells(&text);
    let mesh = m.interface_mesh();
    let n = mesh.positions.len() / 3;
    // both faces: a top and a bottom node per mid-surface node, ± t/2 apart along z
    assert_eq!(n % 2, 0);
    let half = n / 2;
    for i in 0..half {
        let (top, bottom) = (
            &mesh.positions[3 * i..3 * i + 3],
            &mesh.positions[3 * (half + i)..3 * (half + i) + 3],
        );
        assert!((top[2] - T / 2.0).abs() < 1e-15 && (bottom[2] + T / 2.0).abs() < 1e-15);
        assert_eq!([top[0], top[1]], [bottom[0], bottom[1]]);
    }
    // triangles face away from the shell: up on top, down below
    for (k, t) in mesh.triangles.chunks_exact(3).enumerate() {
        let p = |i: u32| {
            [
                mesh.positions[3 * i as usize],
                mesh.positions[3 * i as usize + 1],
                mesh.positions[3 * i as usize + 2],
            ]
        };
        let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
        let nz = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        let top = (t[0] as usize) < half;
        assert!(
            if top { nz > 0.0 } else { nz < 0.0 },
            "triangle {k} faces the wrong way"
        );
    }
    // the side a pressure pushes against: the directors' (+z), the coupled shells' area
    let (area, normal) = m.pressure_surface();
    assert!(
        (area - 0.2 * B).abs() < 1e-12 && (normal[2] - area).abs() < 1e-12,
        "{area} {normal:?}"
    );
    for faces in ["top", "bottom"] {
        let one = shells(&text.replace(
            "[fem.interface]\n",
            &format!("[fem.interface]\nfaces = \"{faces}\"\n"),
        ));
        assert_eq!(one.pressure_surface(), (area, normal), "{faces}");
    }
    // forces on the surfaces: the nodes get the same resultant and moment about the origin
    let mut rng = common::Rng(7);
    let f: Vec<f64> = (0..3 * n).map(|_| rng.next()).collect();
    m.set_interface_forces(&f).unwrap();
    let full = m.external_forces(0.0);
    let (mut f_sum, mut m_surf, mut m_node) = ([0.0; 3], [0.0; 3], [0.0; 3]);
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    for i in 0..n {
        let x = [
            mesh.positions[3 * i],
            mesh.positions[3 * i + 1],
            mesh.positions[3 * i + 2],
        ];
        let fi = [f[3 * i], f[3 * i + 1], f[3 * i + 2]];
        let r = cross(x, fi);
        for c in 0..3 {
            f_sum[c] += fi[c];
            m_surf[c] += r[c];
        }
    }
    let nodes = m.mesh().nodes.clone();
    let mut f_node = [0.0; 3];
    for (k, x) in nodes.iter().enumerate() {
        let fk = [full[6 * k], full[6 * k + 1], full[6 * k + 2]];
        let r = cross(*x, fk);
        for c in 0..3 {
            f_node[c] += fk[c];
            m_node[c] += r[c] + full[6 * k + 3 + c];
        }
    }
    for c in 0..3 {
        assert!((f_sum[c] - f_node[c]).abs() < 1e-12, "force {c}");
        assert!(
            (m_surf[c] - m_node[c]).abs() < 1e-12,
            "moment {c}: {} vs {}",
            m_surf[c],
            m_node[c]
        );
    }
    // kinematics: a few steps under these forces; each face point is the node ± t/2 along
    // the turned director, and its velocity the node's plus ω × r
    for _ in 0..5 {
        m.advance(1e-4).unwrap();
    }
    let (p, v, _) = m.interface_kinematics();
    let (p2, _, _) = {
        let mut copy = shells(&text);
        copy.restore(&m.snapshot()).unwrap();
        copy.set_interface_forces(&f).unwrap();
        copy.advance(1e-9).unwrap();
        copy.interface_kinematics()
    };
    // a finite-difference check of the velocity over 1 ns
    for i in 0..3 * n {
        let fd = (p2[i] - p[i]) / 1e-9;
        assert!(
            (fd - v[i]).abs() < 1e-4 * (1.0 + v.iter().fold(0.0f64, |a, b| a.max(b.abs()))),
            "velocity {i}: {fd} vs {}",
            v[i]
        );
    }
    // top and bottom points stay t apart
    for i in 0..half {
        let d: f64 = (0..3)
            .map(|c| (p[3 * i + c] - p[3 * (half + i) + c]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!((d - T).abs() < 1e-12 * T.max(1.0), "thickness {d}");
    }
}

#[test]
fn snapshot_restore_continues_bitwise_and_outputs_are_written() {
    let text = strip(&format!(
        "[fem.analysis]\ntype = \"dynamic\"\n{}[[fem.probes]]\nname = \"tip\"\npoint = [{L}, 0.0, 0.0]\n",
        tip_load(-5.0)
    ));
    let dir = tempfile::tempdir().unwrap();
    let mut a = fem::build(&config(&text), Path::new(".")).unwrap();
    for _ in 0..3 {
        a.advance(1e-4).unwrap();
        a.write_outputs(dir.path()).unwrap();
    }
    let snap = a.snapshot();
    let mut b = fem::build(&config(&text), Path::new(".")).unwrap();
    b.restore(&snap).unwrap();
    for _ in 0..4 {
        a.advance(1e-4).unwrap();
        b.advance(1e-4).unwrap();
    }
    assert_eq!(a.snapshot(), b.snapshot());
    // nonlinear shells keep a tangent between steps; a restored model rebuilds it from the
    // state it was taken at, and continues bitwise
    let heavy = nonlinear(&text).replace("total = [0.0, 0.0, -5.0]", "total = [0.0, 0.0, -50.0]");
    let mut c = fem::build(&config(&heavy), Path::new(".")).unwrap();
    for _ in 0..5 {
        c.advance(1e-4).unwrap();
    }
    let mut d = fem::build(&config(&heavy), Path::new(".")).unwrap();
    d.restore(&c.snapshot()).unwrap();
    for _ in 0..5 {
        c.advance(1e-4).unwrap();
        d.advance(1e-4).unwrap();
    }
    assert_eq!(c.snapshot(), d.snapshot());
    // a step size change drops the kept tangent in both runs alike
    let snap = c.snapshot();
    let mut e = fem::build(&config(&heavy), Path::new(".")).unwrap();
    e.restore(&snap).unwrap();
    for dt in [5e-5, 5e-5, 1e-4] {
        c.advance(dt).unwrap();
        e.advance(dt).unwrap();
    }
    assert_eq!(c.snapshot(), e.snapshot());
    let iterations = c
        .results()
        .into_iter()
        .find(|(k, _)| k == "newton_iterations_per_solve");
    assert!(
        iterations.as_ref().is_some_and(|(_, n)| *n > 1.0),
        "{iterations:?}"
    );
    let vtu = std::fs::read_to_string(dir.path().join("fem_000003.vtu")).unwrap();
    assert!(vtu.contains("NumberOfCells=\"48\"") && vtu.contains("Name=\"rotation\""));
    assert!(vtu.contains("Name=\"von_mises_top\"") && vtu.contains("Name=\"von_mises_bottom\""));
    let csv = std::fs::read_to_string(dir.path().join("fem_probes.csv")).unwrap();
    assert_eq!(csv.lines().count(), 4, "{csv}");
    let limits = a.limits().unwrap();
    let mass = RHO * L * B * T;
    assert!((limits["structure_mass"] - mass).abs() < 1e-12 * mass);
    assert!(limits["highest_frequency_hz"] > limits["lowest_frequency_hz"]);
    // a snapshot of another model is refused
    let mut other =
        shells(&strip("[fem.analysis]\ntype = \"dynamic\"\n").replace("[24, 2, 0]", "[12, 2, 0]"));
    assert!(other
        .restore(&snap)
        .unwrap_err()
        .to_string()
        .contains("dofs"));
}

#[test]
fn bad_shell_scenes_are_refused_by_name() {
    // refused when the scene is read, or else when the structure is built
    let err = |text: &str, dir: &Path| match fem::parse_scene_section(text) {
        Err(e) => e.to_string(),
        Ok(cfg) => match fem::build(&cfg.unwrap(), dir) {
            Ok(_) => panic!("accepted:\n{text}"),
            Err(e) => e.to_string(),
        },
    };
    let here = Path::new(".");
    // no thickness
    let e = err(
        &strip("").replace(&format!("shell = {{ thickness = {T} }}\n"), ""),
        here,
    );
    assert!(e.contains("fem.shell.thickness"), "{e}");
    // explicit stepping
    let e = err(&strip("[fem.analysis]\ntype = \"explicit\"\n"), here);
    assert!(e.contains("fem.analysis"), "{e}");
    // a plate with two zero sizes
    let e = err(
        &strip("").replace("[0.3, 0.05, 0.0]", "[0.3, 0.0, 0.0]"),
        here,
    );
    assert!(e.contains("fem.mesh.size"), "{e}");
    // shell keys on a volume mesh
    let e = err(
        "[fem]\nmesh = { size = [1.0, 1.0, 1.0], divisions = [1, 1, 1] }\nmaterial = { youngs_modulus = 1e9, poisson_ratio = 0.3, density = 1.0 }\nshell = { thickness = 0.01 }\n",
        here,
    );
    assert!(e.contains("fem.shell"), "{e}");
    // settings that do not apply to (linear) shells
    let e = err(&strip("[fem.newton]\nincrements = 3\n"), here);
    assert!(e.contains("fem.newton") && e.contains("nonlinear"), "{e}");
    let e = err(
        &strip("").replace("[fem]\n", "[fem]\nsolver = \"mixed\"\n"),
        here,
    );
    assert!(e.contains("fem.solver"), "{e}");
    let e = err(&nonlinear(&strip("[fem.newton]\nalways = true\n")), here);
    assert!(e.contains("fem.newton.always"), "{e}");
    // probes: a point off the strip, a node that is not one of it
    let e = err(
        &strip("[[fem.probes]]\nname = \"off\"\npoint = [0.15, 0.025, 1.0]\n"),
        here,
    );
    assert!(
        e.contains("fem.probes[0] 'off'") && e.contains("farther than the longest shell edge"),
        "{e}"
    );
    let e = err(
        &strip("[[fem.probes]]\nname = \"gone\"\nnode = 999999\n"),
        here,
    );
    assert!(
        e.contains("fem.probes[0] 'gone': node 999999 is not a shell node"),
        "{e}"
    );
    // a support of rotations only is a support
    let rotations_only =
        strip("") + "[[fem.supports]]\non = { set = \"xmax\" }\nfix = []\nrotations = [\"x\"]\n";
    assert!(fem::build(&config(&rotations_only), here).is_ok());
    let dir = tempfile::tempdir().unwrap();
    let mat = "material = { youngs_modulus = 1e9, poisson_ratio = 0.3, density = 1.0 }\n";
    // a shell too thick for its curvature: a quarter cylinder of radius 10 mm, 40 mm thick
    let mut inp = String::from("*NODE\n");
    for j in 0..2 {
        for i in 0..=4 {
            let phi = std::f64::consts::FRAC_PI_2 * i as f64 / 4.0;
            let (x, y, z) = (0.01 * phi.cos(), 0.01 * phi.sin(), 0.01 * j as f64);
            inp.push_str(&format!("{}, {x}, {y}, {z}\n", j * 5 + i + 1));
        }
    }
    inp.push_str("*ELEMENT, TYPE=S4, ELSET=A\n");
    for i in 0..4 {
        inp.push_str(&format!(
            "{}, {}, {}, {}, {}\n",
            i + 1,
            i + 1,
            i + 6,
            i + 7,
            i + 2
        ));
    }
    inp.push_str("*SHELL SECTION, ELSET=A, MATERIAL=S\n0.04\n");
    std::fs::write(dir.path().join("thick.inp"), inp).unwrap();
    let e = err(&format!("[fem]\nmesh = \"thick.inp\"\n{mat}"), dir.path());
    assert!(e.contains("thick.inp:") && e.contains("curvature"), "{e}");
    // a probe on a node of the file that no shell uses
    std::fs::write(
        dir.path().join("orphan.inp"),
        "*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n3, 1, 1, 0\n4, 0, 1, 0\n9, 0.5, 0.5, 0\n\
         *ELEMENT, TYPE=S4, ELSET=A\n1, 1, 2, 3, 4\n*SHELL SECTION, ELSET=A, MATERIAL=S\n0.01\n",
    )
    .unwrap();
    let e = err(
        &format!("[fem]\nmesh = \"orphan.inp\"\n{mat}[[fem.probes]]\nname = \"lone\"\nnode = 9\n"),
        dir.path(),
    );
    assert!(
        e.contains("fem.probes[0] 'lone': node 9 is not a shell node"),
        "{e}"
    );
    // a solid deck keeps parsing with shell sections a shell model could not use
    std::fs::write(
        dir.path().join("solid.inp"),
        "*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n3, 1, 1, 0\n4, 0, 1, 0\n5, 0, 0, 1\n6, 1, 0, 1\n7, 1, 1, 1\n8, 0, 1, 1\n\
         *ELEMENT, TYPE=C3D8, ELSET=BODY\n1, 1, 2, 3, 4, 5, 6, 7, 8\n\
         *ELEMENT, TYPE=S3, ELSET=SKIN\n2, 1, 2, 3\n\
         *SHELL SECTION, ELSET=SKIN, MATERIAL=S, COMPOSITE\n0.001, 3, S\n0.002, 3, S\n\
         *SHELL SECTION, ELSET=NOWHERE, MATERIAL=S\n0.001\n",
    )
    .unwrap();
    assert!(fem::Mesh::read(&dir.path().join("solid.inp")).is_ok());
    // a fold: two shells at 90°
    std::fs::write(
        dir.path().join("fold.inp"),
        "*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n3, 1, 1, 0\n4, 0, 1, 0\n5, 1, 0, 1\n6, 1, 1, 1\n\
         *ELEMENT, TYPE=S4, ELSET=A\n1, 1, 2, 3, 4\n2, 2, 5, 6, 3\n*SHELL SECTION, ELSET=A, MATERIAL=S\n0.01\n",
    )
    .unwrap();
    let e = err(&format!("[fem]\nmesh = \"fold.inp\"\n{mat}"), dir.path());
    assert!(e.contains("fold.inp:") && e.contains("fold"), "{e}");
    // triangles
    std::fs::write(
        dir.path().join("tri.inp"),
        "*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n3, 1, 1, 0\n*ELEMENT, TYPE=S3, ELSET=A\n7, 1, 2, 3\n",
    )
    .unwrap();
    let e = err(
        &format!("[fem]\nmesh = \"tri.inp\"\n{mat}shell = {{ thickness = 0.01 }}\n"),
        dir.path(),
    );
    assert!(e.contains("tri.inp:6") && e.contains("element 7"), "{e}");
    // a *SHELL SECTION of an unknown set
    std::fs::write(
        dir.path().join("set.inp"),
        "*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n3, 1, 1, 0\n4, 0, 1, 0\n*ELEMENT, TYPE=S4, ELSET=A\n1, 1, 2, 3, 4\n\
         *SHELL SECTION, ELSET=B, MATERIAL=S\n0.01\n",
    )
    .unwrap();
    let e = err(&format!("[fem]\nmesh = \"set.inp\"\n{mat}"), dir.path());
    assert!(e.contains("set.inp:8") && e.contains("'B'"), "{e}");
}

/// A scene of `strip` with geometrically nonlinear shells.
fn nonlinear(text: &str) -> String {
    let linear = format!("shell = {{ thickness = {T} }}");
    assert!(text.contains(&linear));
    text.replace(
        &linear,
        &format!("shell = {{ thickness = {T}, nonlinear = true }}"),
    )
}

#[test]
fn large_deflection_cantilever_follows_the_elastica() {
    // Mattiasson (1981): a cantilever under a dead tip load P, k = P L² / EI; tip deflection w
    // and shortening u over L from the elliptic integrals
    let i = B * T.powi(3) / 12.0;
    for (k, u_ref, w_ref) in [(1.0, 0.05643, 0.30172), (4.0, 0.32894, 0.66996)] {
        let p = -k * E * i / (L * L);
        let text = nonlinear(&strip(&format!(
            "{}[fem.newton]\nincrements = 8\n[[fem.probes]]\nname = \"tip\"\npoint = [{L}, 0.0, 0.0]\n",
            tip_load(p)
        )));
        let mut m = shells(&text);
        m.solve_static().unwrap();
        let d = m.probe_displacement("tip").unwrap();
        let (u, w) = (-d[0] / L, -d[2] / L);
        eprintln!(
            "k = {k}: w/L = {w:.5} ({w_ref}, {:+.2} %), u/L = {u:.5} ({u_ref}, {:+.2} %); {} iterations",
            100.0 * (w / w_ref - 1.0),
            100.0 * (u / u_ref - 1.0),
            m.last_newton_residuals().len()
        );
        assert!((w / w_ref - 1.0).abs() < 1e-2, "k = {k}: w/L {w}");
        // the root's bending stress follows the lever arm the load has on the bent strip
        // (L − u), not L
        let sigma = -p * (L * (1.0 - u) - L / 48.0) * (T / 2.0) / i;
        let top = m.surface_stresses()[0][0][0];
        eprintln!("k = {k}: root stress {top:.4e} Pa, |P| (L − u − x) c / I {sigma:.4e} Pa");
        assert!(
            (top / sigma - 1.0).abs() < 1e-2,
            "k = {k}: root stress {top}"
        );
        assert!((u / u_ref - 1.0).abs() < 2e-2, "k = {k}: u/L {u}");
    }
}

#[test]
fn nonlinear_dynamics_reduce_to_the_linear_at_small_amplitude() {
    let dynamic = "[fem.analysis]\ntype = \"dynamic\"\nalpha_b = -0.1\n";
    let mut lin = shells(&strip(&format!("{dynamic}{}", tip_load(-1e-3))));
    let mut nl = shells(&nonlinear(&strip(&format!("{dynamic}{}", tip_load(-1e-3)))));
    for _ in 0..40 {
        lin.advance(5e-4).unwrap();
        nl.advance(5e-4).unwrap();
    }
    let (a, b) = (lin.displacements(), nl.displacements());
    let scale = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let diff = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    eprintln!("small amplitude: max |u_nl − u_lin| = {diff:.2e} of {scale:.2e}");
    assert!(scale > 0.0 && diff < 1e-4 * scale);
}
