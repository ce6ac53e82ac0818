//! Sensors (`[[dem.sensors]]`): measurements sampled at every `write_outputs` call, written to
//! `dem_sensors.csv` (one column per sensor) and summarised in the results as
//! `sensor.<name>.last`, `.max` and `.mean`.
//!
//! - **flow**: net mass through the plane `axis = value` in the negative axis direction. Every
//!   step after the drift, each particle's side of the plane (kept per particle id, so the
//!   broad phase's re-sorting does not matter) is compared with its side before: a particle
//!   that went from above (> value) to on/below counts +m, the other way −m, when its new
//!   position lies inside the optional rectangle. The sampled value is the rate (kg/s) over
//!   the interval since the previous sample; `sensor.<name>.mass` is the cumulative mass and
//!   `.mean` the mass over the whole sensing time.
//! - **pressure**: normal stress (Pa, compression positive) through the rectangle of the plane
//!   `axis = value`: the axis component of the force on the upper body (the one on the +axis
//!   side) of every particle–particle contact whose centre-to-centre segment crosses the plane
//!   inside the rectangle, and of every particle–wall contact whose particle centre and contact
//!   point lie on opposite sides with the crossing inside the rectangle, over the area. The
//!   contact forces are re-evaluated by the engine's contact law from the current state
//!   (elastic, damping and the stored tangential history; no history increment); those of
//!   non-spherical bodies (superquadrics, polyhedra) are their contact records of the last
//!   force evaluation, which saw the same state.
//! - **repose**: angle of repose (degrees) of a heap around the vertical axis through
//!   `centre`: particles with radial distance ρ in [r_min, r_max] are binned by ρ; per bin the
//!   particle with the highest top z + r gives a point (ρ, z + r); a least-squares line through
//!   those points gives the slope s and the angle atan |s|. NaN with fewer than two bins.
//!
//! Sums run in storage order, which does not depend on the thread count, so sensor values are
//! bitwise identical for any number of threads.

use crate::broad_phase::NeighbourLists;
use crate::config::{Axis, SensorConfig};
use crate::hertz_mindlin::V3;
use crate::particles::Particles;
use crate::resolve_forces::{pair_contact, wall_contact, wall_group, ForceContext, Kinematics};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Particles per parallel chunk of the flow check (the result does not depend on it).
const CHUNK: usize = 4096;

/// Mutable state of all sensors (part of snapshots).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct SensorState {
    /// One per sensor, in scene order.
    pub sensors: Vec<SensorRecord>,
    /// Time the sensing started (flow sides initialised).
    pub start_time: f64,
    /// Time of the last sample, `None` before the first.
    pub last_sample_time: Option<f64>,
}

/// State and statistics of one sensor.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct SensorRecord {
    /// Flow: 1 if the particle with that id is above the plane (> value), else 0.
    pub side_by_id: Vec<u8>,
    /// Flow: cumulative net mass passed (kg), now and at the last sample.
    pub mass: f64,
    pub mass_at_sample: f64,
    /// Last and largest sampled value, sum and number of samples.
    pub last: f64,
    pub max: f64,
    pub sum: f64,
    pub samples: u64,
}

fn side(x: &V3, axis: usize, value: f64) -> u8 {
    u8::from(x[axis] > value)
}

fn inside(x: &V3, plane: [usize; 2], min: &[f64; 2], max: &[f64; 2]) -> bool {
    (0..2).all(|c| x[plane[c]] >= min[c] && x[plane[c]] < max[c])
}

impl SensorState {
    /// Fresh state at time `time`: flow sensors note each particle's side of their plane.
    pub fn new(cfgs: &[SensorConfig], p: &Particles, time: f64) -> SensorState {
        let mut s = SensorState {
            sensors: vec![SensorRecord::default(); cfgs.len()],
            start_time: time,
            last_sample_time: None,
        };
        for (cfg, rec) in cfgs.iter().zip(&mut s.sensors) {
            if let SensorConfig::Flow { axis, value, .. } = cfg {
                init_sides(rec, p, axis.indices().0, *value);
            }
        }
        s
    }

    /// Books the plane crossings of the last drift (call after every drift).
    pub fn track_flow(&mut self, cfgs: &[SensorConfig], p: &Particles) {
        for (cfg, rec) in cfgs.iter().zip(&mut self.sensors) {
            let SensorConfig::Flow {
                axis,
                value,
                min,
                max,
                ..
            } = cfg
            else {
                continue;
            };
            let (a, plane) = axis.indices();
            // ids are 0..n (insertion order); sinks remove particles, so fewer than n may be left
            if p.len() > rec.side_by_id.len() {
                // particles were added: start over from where they are
                init_sides(rec, p, a, *value);
                continue;
            }
            let sides = &rec.side_by_id;
            let changes: Vec<Vec<(u32, u8, f64)>> = (
                p.position.par_chunks(CHUNK),
                p.id.par_chunks(CHUNK),
                p.mass.par_chunks(CHUNK),
            )
                .into_par_iter()
                .map(|(xs, ids, ms)| {
                    let mut out = Vec::new();
                    for ((x, &id), &m) in xs.iter().zip(ids).zip(ms) {
                        let s = side(x, a, *value);
                        // an id beyond the table cannot occur (checked above); skip, not panic
                        if sides.get(id as usize).is_some_and(|&old| s != old) {
                            let counted = match (min, max) {
                                (Some(lo), Some(hi)) => inside(x, plane, lo, hi),
                                _ => true,
                            };
                            // downwards (negative axis direction) counts positive
                            let dm = if !counted {
                                0.0
                            } else if s == 0 {
                                m
                            } else {
                                -m
                            };
                            out.push((id, s, dm));
                        }
                    }
                    out
                })
                .collect();
            for (id, s, dm) in changes.into_iter().flatten() {
                rec.side_by_id[id as usize] = s;
                rec.mass += dm;
            }
        }
    }

    /// Samples every sensor at time `time` and updates the statistics; returns the CSV row
    /// (columns as [`column_names`]), or `None` if a sample was already taken at this time.
    pub fn sample(
        &mut self,
        cfgs: &[SensorConfig],
        time: f64,
        p: &Particles,
        lists: &NeighbourLists,
        ctx: &ForceContext,
    ) -> Option<Vec<f64>> {
        if self.last_sample_time == Some(time) {
            return None;
        }
        let since = self.last_sample_time.unwrap_or(self.start_time);
        let mut row = Vec::new();
        for (cfg, rec) in cfgs.iter().zip(&mut self.sensors) {
            let value = match cfg {
                SensorConfig::Flow { .. } => {
                    let rate = if time > since {
                        (rec.mass - rec.mass_at_sample) / (time - since)
                    } else {
                        0.0
                    };
                    rec.mass_at_sample = rec.mass;
                    rate
                }
                _ => current_value(cfg, p, lists, ctx),
            };
            if value.is_finite() {
                rec.max = if rec.samples == 0 {
                    value
                } else {
                    rec.max.max(value)
                };
                rec.sum += value;
                rec.samples += 1;
            }
            rec.last = value;
            row.push(value);
            if matches!(cfg, SensorConfig::Flow { .. }) {
                row.push(rec.mass);
            }
        }
        self.last_sample_time = Some(time);
        Some(row)
    }

    /// `sensor.<name>.last`, `.max`, `.mean` (and `.mass` for flow) of the samples so far;
    /// before the first sample, the current value (flow: the mean rate since the start).
    pub fn results(
        &self,
        cfgs: &[SensorConfig],
        time: f64,
        p: &Particles,
        lists: &NeighbourLists,
        ctx: &ForceContext,
    ) -> Vec<(String, f64)> {
        let mut out = Vec::new();
        for (cfg, rec) in cfgs.iter().zip(&self.sensors) {
            let key = |what: &str| format!("sensor.{}.{what}", cfg.name());
            let flow = matches!(cfg, SensorConfig::Flow { .. });
            let (last, max, mean) = if flow {
                let t_end = self.last_sample_time.unwrap_or(time);
                let m_end = if self.last_sample_time.is_some() {
                    rec.mass_at_sample
                } else {
                    rec.mass
                };
                let mean = if t_end > self.start_time {
                    m_end / (t_end - self.start_time)
                } else {
                    0.0
                };
                if rec.samples == 0 {
                    (mean, mean, mean)
                } else {
                    (rec.last, rec.max, mean)
                }
            } else if rec.samples == 0 {
                let v = current_value(cfg, p, lists, ctx);
                (v, v, v)
            } else {
                (rec.last, rec.max, rec.sum / rec.samples as f64)
            };
            out.push((key("last"), last));
            out.push((key("max"), max));
            out.push((key("mean"), mean));
            if flow {
                out.push((key("mass"), rec.mass));
            }
        }
        out
    }
}

/// Column names of `dem_sensors.csv` after `time`: the sensor name (its value), and for flow
/// sensors also `<name>.mass` (cumulative kg).
pub fn column_names(cfgs: &[SensorConfig]) -> Vec<String> {
    let mut c = Vec::new();
    for cfg in cfgs {
        c.push(cfg.name().to_string());
        if matches!(cfg, SensorConfig::Flow { .. }) {
            c.push(format!("{}.mass", cfg.name()));
        }
    }
    c
}

fn init_sides(rec: &mut SensorRecord, p: &Particles, axis: usize, value: f64) {
    let ids = p.id.iter().map(|&i| i as usize + 1).max().unwrap_or(0);
    rec.side_by_id = vec![0; ids];
    for (x, &id) in p.position.iter().zip(&p.id) {
        rec.side_by_id[id as usize] = side(x, axis, value);
    }
}

/// The current value of a pressure or repose sensor (flow sensors need an interval: NaN).
fn current_value(
    cfg: &SensorConfig,
    p: &Particles,
    lists: &NeighbourLists,
    ctx: &ForceContext,
) -> f64 {
    match cfg {
        SensorConfig::Flow { .. } => f64::NAN,
        SensorConfig::Pressure {
            axis,
            value,
            min,
            max,
            ..
        } => pressure(*axis, *value, min, max, p, lists, ctx),
        SensorConfig::Repose {
            centre,
            r_min,
            r_max,
            bin_width,
            along,
            ..
        } => {
            let w = bin_width
                .unwrap_or_else(|| 2.0 * p.radius.iter().sum::<f64>() / p.len().max(1) as f64);
            angle_of_repose(p, *centre, *r_min, *r_max, w, *along)
        }
    }
}

/// Normal stress through the rectangle [min, max] of the plane `axis = value` (see the module
/// docs); NaN when the neighbour lists are not current.
pub fn pressure(
    axis: Axis,
    value: f64,
    min: &[f64; 2],
    max: &[f64; 2],
    p: &Particles,
    lists: &NeighbourLists,
    ctx: &ForceContext,
) -> f64 {
    let n = p.len();
    if !lists.valid || lists.first_pair.len() != n + 1 || lists.wall_start.len() != n + 1 {
        return f64::NAN;
    }
    let (a, plane) = axis.indices();
    let area = (max[0] - min[0]) * (max[1] - min[1]);
    let k = Kinematics::of(p);
    let crossing = |x: &V3, y: &V3| -> Option<V3> {
        if side(x, a, value) == side(y, a, value) {
            return None;
        }
        let t = (value - x[a]) / (y[a] - x[a]);
        let c = x + (y - x) * t;
        inside(&c, plane, min, max).then_some(c)
    };
    let mut force = 0.0;
    for i in 0..n {
        let xi = p.position[i];
        for pk in lists.first_pair[i] as usize..lists.first_pair[i + 1] as usize {
            let j = lists.partner[pk] as usize;
            let xj = p.position[j];
            let d = xi - xj;
            let (dist2, sum) = (d.norm_squared(), p.radius[i] + p.radius[j]);
            if dist2 >= sum * sum || crossing(&xi, &xj).is_none() {
                continue;
            }
            let mut shear = lists.shear[pk];
            let c = pair_contact(&k, ctx, (i, j), d, dist2, p.velocity[j], &mut shear);
            // force on the body on the +axis side
            force += if xi[a] > value {
                c.cf.force[a]
            } else {
                -c.cf.force[a]
            };
        }
        let cands = &lists.walls[lists.wall_start[i] as usize..lists.wall_start[i + 1] as usize];
        let mut g = 0;
        while g < cands.len() {
            let first = lists.wall_start[i] as usize + g;
            let (geo, next) = wall_group(xi, p.radius[i], cands, g, ctx);
            g = next;
            let Some(geo) = geo else { continue };
            if crossing(&xi, &geo.point).is_none() {
                continue;
            }
            let mut shear = lists.wall_contacts[first].shear;
            let cf = wall_contact(&k, ctx, i, &geo, &mut shear);
            force += if xi[a] > value {
                cf.force[a]
            } else {
                -cf.force[a]
            };
        }
    }
    // the contacts of non-spherical bodies: their records of the last force evaluation (the
    // state the sample sees), force on the first body
    for (&[i, j], c) in lists.shaped_pairs.iter().zip(&lists.shaped_pair_contacts) {
        let (xi, xj) = (p.position[i as usize], p.position[j as usize]);
        if c.touching() && crossing(&xi, &xj).is_some() {
            force += if xi[a] > value {
                c.force[a]
            } else {
                -c.force[a]
            };
        }
    }
    let walls = (lists.shaped_walls.iter().map(|w| w[0]))
        .zip(&lists.shaped_wall_contacts)
        .chain((lists.shaped_mesh.iter().map(|m| m.0)).zip(&lists.shaped_mesh_contacts));
    for (i, c) in walls {
        let xi = p.position[i as usize];
        if c.touching() && crossing(&xi, &c.point).is_some() {
            force += if xi[a] > value {
                c.force[a]
            } else {
                -c.force[a]
            };
        }
    }
    force / area
}

/// Angle of repose in degrees (see the module docs).
pub fn angle_of_repose(
    p: &Particles,
    centre: [f64; 2],
    r_min: f64,
    r_max: f64,
    bin_width: f64,
    along: Option<Axis>,
) -> f64 {
    // only the occupied bins are stored: a narrow `bin_width` over a wide ring must not
    // allocate a bin per width (the count saturates instead of overflowing)
    let bins = (((r_max - r_min) / bin_width).ceil() as usize).max(1);
    let mut top: std::collections::BTreeMap<usize, (f64, f64)> = Default::default();
    for (x, r) in p.position.iter().zip(&p.radius) {
        let rho = match along {
            Some(Axis::X) => (x.x - centre[0]).abs(),
            Some(Axis::Y) => (x.y - centre[1]).abs(),
            _ => (x.x - centre[0]).hypot(x.y - centre[1]),
        };
        if !(rho >= r_min && rho <= r_max) {
            continue;
        }
        let b = (((rho - r_min) / bin_width) as usize).min(bins - 1);
        let h = x.z + r;
        let slot = top.entry(b).or_insert((rho, h));
        if h > slot.1 {
            *slot = (rho, h);
        }
    }
    let pts: Vec<(f64, f64)> = top.into_values().collect();
    if pts.len() < 2 {
        return f64::NAN;
    }
    let m = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|q| q.0).sum::<f64>() / m,
        pts.iter().map(|q| q.1).sum::<f64>() / m,
    );
    let sxy: f64 = pts.iter().map(|q| (q.0 - mx) * (q.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|q| (q.0 - mx).powi(2)).sum();
    if sxx == 0.0 {
        return f64::NAN;
    }
    (sxy / sxx).abs().atan().to_degrees()
}
