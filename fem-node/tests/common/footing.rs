//! The strip-footing plasticity benchmark, shared by the test and the `nonlinear` bench.

/// Collapse pressure of a rough rigid strip footing (half-width b = 1 m, symmetry at x = 0,
/// plane strain) pushed into a purely cohesive soil (Tresca: Mohr–Coulomb with φ = ψ = 0,
/// c = 10 kPa) on a 5 m × 5 m half-domain of hex8b elements of size `h` (B̄: the plastic flow is
/// isochoric). Returns the pressure–settlement curve, Newton iterations and wall time.
pub fn strip_footing(h: f64, steps: usize) -> (Vec<(f64, f64)>, usize, f64) {
    let c = 1e4;
    let scene = format!(
        "[fem]\nmesh = {{ size = [5.0, {h}, 5.0], origin = [0.0, 0.0, -5.0], element_size = {h}, \
         element = \"hex8b\" }}\n\
         [fem.materials.clay]\nmodel = \"mohr_coulomb\"\nyoungs_modulus = 1e7\npoisson_ratio = 0.3\n\
         friction_angle = 0.0\ndilation_angle = 0.0\ncohesion = {c}\ndensity = 1800.0\n\
         [[fem.sections]]\nelements = \"all\"\nmaterial = \"clay\"\n\
         [[fem.supports]]\non = {{ set = \"ymin\" }}\nfix = [\"y\"]\n\
         [[fem.supports]]\non = {{ set = \"ymax\" }}\nfix = [\"y\"]\n\
         [[fem.supports]]\non = {{ set = \"xmin\" }}\nfix = [\"x\"]\n\
         [[fem.supports]]\non = {{ set = \"xmax\" }}\nfix = [\"x\"]\n\
         [[fem.supports]]\non = {{ set = \"zmin\" }}\n\
         [[fem.supports]]\non = {{ box = {{ min = [-0.01, -1.0, -0.01], max = [1.01, 1.0, 0.01] }} }}\n\
         [fem.newton]\nmax_iterations = 40\n"
    );
    let cfg = fem::parse_scene_section(&scene).unwrap().unwrap();
    let mut m = fem::Model::from_config(&cfg, std::path::Path::new(".")).unwrap();
    let footing: Vec<usize> = (0..m.mesh().num_nodes())
        .filter(|&n| {
            let x = m.mesh().nodes[n];
            x[2] == 0.0 && x[0] <= 1.0 + 1e-9
        })
        .collect();
    let t0 = std::time::Instant::now();
    let mut curve = Vec::new();
    let mut iterations = 0;
    for step in 1..=steps {
        // 1 mm steps through the elastic range, then 5 mm
        let settlement = if step <= 8 {
            1e-3 * step as f64
        } else {
            8e-3 + 5e-3 * (step - 8) as f64
        };
        for &n in &footing {
            m.set_prescribed_displacement(3 * n + 2, -settlement)
                .unwrap();
        }
        m.advance(1.0).unwrap();
        iterations += m
            .last_newton_residuals()
            .iter()
            .map(|h| h.len() - 1)
            .sum::<usize>();
        let r = m.reactions();
        let force: f64 = footing.iter().map(|&n| r[3 * n + 2]).sum();
        curve.push((settlement, force.abs() / h));
    }
    (curve, iterations, t0.elapsed().as_secs_f64())
}
