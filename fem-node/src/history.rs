//! Load histories h(t): a load's spatial pattern is scaled by h(t) (nodal forces, pressures).

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A scalar function of time, built from tables, sines and constants with scale factors,
/// sums, products and time windows. TOML: an inline table with `type = "..."`.
///
/// The sleeper load pattern of Ullrich ch. 6 (REFERENCE A5: ramp 0→220 kN, cycles 4.4–44 kN at
/// 2 Hz, ramp again) is a `sum` of a `table` (the two ramps) and a `window` around
/// `24.2 kN + 19.8 kN · sin(2π·2 t)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum History {
    /// h = value
    Constant { value: f64 },
    /// Piecewise linear through `points = [[t, h], ...]` (t non-decreasing; a repeated t is a
    /// jump, the later point wins at and after it); constant beyond the ends.
    Table { points: Vec<[f64; 2]> },
    /// h = offset + amplitude · sin(2π · frequency · (t − start) + phase); frequency in Hz,
    /// phase in rad.
    Sine {
        amplitude: f64,
        frequency: f64,
        #[serde(default)]
        phase: f64,
        #[serde(default)]
        offset: f64,
        #[serde(default)]
        start: f64,
    },
    /// h = of(t) for start ≤ t < end, else 0.
    Window {
        start: f64,
        end: f64,
        of: Box<History>,
    },
    /// h = factor · of(t)
    Scale { factor: f64, of: Box<History> },
    /// h = Σ of_i(t)
    Sum { of: Vec<History> },
    /// h = Π of_i(t)
    Product { of: Vec<History> },
    /// The named history `[fem.histories.<name>]`.
    Ref { name: String },
}

impl History {
    /// Evaluates h(t); `named` resolves `ref` entries (cycles are rejected at validation).
    pub fn eval(&self, t: f64, named: &BTreeMap<String, History>) -> f64 {
        self.eval_depth(t, named, 0)
    }

    fn eval_depth(&self, t: f64, named: &BTreeMap<String, History>, depth: usize) -> f64 {
        if depth > 64 {
            return f64::NAN;
        }
        match self {
            History::Constant { value } => *value,
            History::Table { points } => table(points, t),
            History::Sine {
                amplitude,
                frequency,
                phase,
                offset,
                start,
            } => {
                offset
                    + amplitude
                        * (2.0 * std::f64::consts::PI * frequency * (t - start) + phase).sin()
            }
            History::Window { start, end, of } => {
                if t >= *start && t < *end {
                    of.eval_depth(t, named, depth + 1)
                } else {
                    0.0
                }
            }
            History::Scale { factor, of } => factor * of.eval_depth(t, named, depth + 1),
            History::Sum { of } => of.iter().map(|h| h.eval_depth(t, named, depth + 1)).sum(),
            History::Product { of } => of
                .iter()
                .map(|h| h.eval_depth(t, named, depth + 1))
                .product(),
            History::Ref { name } => named
                .get(name)
                .map_or(f64::NAN, |h| h.eval_depth(t, named, depth + 1)),
        }
    }

    /// Structural checks: returns (path suffix, message) of the first problem.
    pub fn validate(
        &self,
        named: &BTreeMap<String, History>,
        depth: usize,
    ) -> Result<(), (String, String)> {
        if depth > 32 {
            return Err((
                String::new(),
                "history nesting too deep or cyclic `ref`".into(),
            ));
        }
        let finite = |v: f64, f: &str| {
            if v.is_finite() {
                Ok(())
            } else {
                Err((f.to_string(), "must be finite".to_string()))
            }
        };
        match self {
            History::Constant { value } => finite(*value, "value"),
            History::Table { points } => {
                if points.is_empty() {
                    return Err((
                        "points".into(),
                        "table needs at least one [t, value] point".into(),
                    ));
                }
                for (i, p) in points.iter().enumerate() {
                    if !p[0].is_finite() || !p[1].is_finite() {
                        return Err((format!("points[{i}]"), "must be finite".into()));
                    }
                    if i > 0 && p[0] < points[i - 1][0] {
                        return Err((
                            format!("points[{i}]"),
                            "times must be non-decreasing".into(),
                        ));
                    }
                }
                Ok(())
            }
            History::Sine {
                amplitude,
                frequency,
                phase,
                offset,
                start,
            } => {
                finite(*amplitude, "amplitude")?;
                finite(*phase, "phase")?;
                finite(*offset, "offset")?;
                finite(*start, "start")?;
                if !(frequency.is_finite() && *frequency >= 0.0) {
                    return Err(("frequency".into(), "must be ≥ 0 Hz".into()));
                }
                Ok(())
            }
            History::Window { start, end, of } => {
                if !(start <= end) {
                    return Err(("end".into(), "must be ≥ start".into()));
                }
                of.validate(named, depth + 1)
                    .map_err(|(p, m)| (format!("of.{p}"), m))
            }
            History::Scale { factor, of } => {
                finite(*factor, "factor")?;
                of.validate(named, depth + 1)
                    .map_err(|(p, m)| (format!("of.{p}"), m))
            }
            History::Sum { of } | History::Product { of } => {
                for (i, h) in of.iter().enumerate() {
                    h.validate(named, depth + 1)
                        .map_err(|(p, m)| (format!("of[{i}].{p}"), m))?;
                }
                Ok(())
            }
            History::Ref { name } => match named.get(name) {
                None => Err((
                    "name".into(),
                    format!(
                        "unknown history '{name}' (defined: {})",
                        named.keys().cloned().collect::<Vec<_>>().join(", ")
                    ),
                )),
                Some(h) => h.validate(named, depth + 1),
            },
        }
    }
}

fn table(points: &[[f64; 2]], t: f64) -> f64 {
    if points.is_empty() {
        return 0.0;
    }
    if t < points[0][0] {
        return points[0][1];
    }
    // last i with t_i ≤ t
    let i = points.partition_point(|p| p[0] <= t) - 1;
    if i + 1 >= points.len() {
        return points[points.len() - 1][1];
    }
    let (p, q) = (points[i], points[i + 1]);
    if q[0] == p[0] {
        return q[1];
    }
    p[1] + (q[1] - p[1]) * (t - p[0]) / (q[0] - p[0])
}
