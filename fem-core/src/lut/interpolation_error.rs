//! How much interpolation across the modulus axis adds to a table's contact radius.
//!
//! The fit reads a(u_s) between the table's moduli by PCHIP in ln E2 at fixed u_s. Each
//! interior modulus node k is left out and predicted from its neighbours k-2, k-1, k+1 and
//! k+2 (those the table holds); the difference from the stored curve, at u_s every
//! [`U_S_STEP_MM`] that all of them reach, is the error of the same interpolant at twice the
//! grid spacing. On smooth curves that is larger than the error at the table's own spacing
//! (PCHIP is of order 2-3). A feature narrower than the spacing can escape both, so this is
//! a screening figure, not a bound. The example `interpolation_error` measures the error at
//! the table's own spacing against direct solves.
//!
//! Across p_air the same is done at every modulus node: each interior inflated pressure node
//! is left out and read from the other inflated nodes by the table's cubic in p_air
//! ([`super::pressure_weights`], with the outer nodes that exist), over the u_s every curve
//! involved reaches. The example `interpolation_error -- TABLE --truth FILE` measures the
//! error at the table's own spacing against direct solves between the pressure nodes.

use super::grid::GridIndex;
use super::pchip;
use super::pressure_weights;
use super::table::{Lut, LutCurve};

/// Spacing of the u_s points compared (mm).
pub const U_S_STEP_MM: f64 = 0.02;
/// Smallest u_s compared (mm): below it the contact is a few mesh nodes wide and the fit
/// does not use it either.
pub const U_S_MIN_MM: f64 = 0.2;

/// The leave-one-out interpolation error in a at one pressure, over every slice of the
/// effect axes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ModulusInterpolationError {
    pub pressure_kpa: f64,
    /// Largest |prediction - stored a| over the left-out nodes, u_s and slices (µm).
    pub max_um: f64,
    /// RMS over the same points (µm).
    pub rms_um: f64,
    /// The left-out modulus where the largest difference sits (kPa).
    pub worst_modulus_kpa: f64,
    /// Points compared.
    pub points: usize,
    /// Slices of the effect axes compared (1 in a table without an effect axis).
    pub slices: usize,
}

/// a at `u_s` along a stored curve, linear between load steps (the first bracketing step
/// pair), `None` outside the curve.
fn a_at(curve: &LutCurve, u_s: f64) -> Option<f64> {
    curve
        .u_s_mm
        .windows(2)
        .zip(curve.a_mm.windows(2))
        .find(|(u, _)| u[0] <= u_s && u_s <= u[1] && u[1] > u[0])
        .map(|(u, a)| a[0] + (u_s - u[0]) / (u[1] - u[0]) * (a[1] - a[0]))
}

fn max_u_s(curve: &LutCurve) -> f64 {
    curve
        .u_s_mm
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Every slice of the effect axes: (stiffening, material, friction, thickness) indices.
fn effect_slices(lut: &Lut) -> Vec<(usize, usize, usize, usize)> {
    let e = &lut.grid.effects;
    let mut slices = Vec::new();
    for stiffening in 0..e.stiffening.len() {
        for material in 0..e.material.len() {
            for friction in 0..e.friction.len() {
                for thickness in 0..e.sample_thickness_mm.len() {
                    slices.push((stiffening, material, friction, thickness));
                }
            }
        }
    }
    slices
}

/// The u_s compared up to `reach`: from [`U_S_MIN_MM`] every [`U_S_STEP_MM`], on a fixed
/// lattice (a running sum would lose the last point to rounding).
fn u_s_lattice(reach: f64) -> impl Iterator<Item = f64> {
    let count = ((reach - U_S_MIN_MM) / U_S_STEP_MM + 1e-9).floor();
    (0..=(count.max(-1.0) as i64)).map(|i| U_S_MIN_MM + i as f64 * U_S_STEP_MM)
}

/// Largest and summed squared differences (µm) over the points compared, and where the
/// largest sits.
#[derive(Debug, Clone, Copy)]
struct Tally {
    max_um: f64,
    sum_sq: f64,
    points: usize,
    worst_modulus_kpa: f64,
}

impl Tally {
    fn new() -> Self {
        Self {
            max_um: 0.0,
            sum_sq: 0.0,
            points: 0,
            worst_modulus_kpa: f64::NAN,
        }
    }

    fn add(&mut self, prediction_mm: f64, stored_mm: f64, modulus_kpa: f64) {
        let d_um = 1e3 * (prediction_mm - stored_mm).abs();
        if d_um > self.max_um {
            self.max_um = d_um;
            self.worst_modulus_kpa = modulus_kpa;
        }
        self.sum_sq += d_um * d_um;
        self.points += 1;
    }

    fn rms_um(&self) -> f64 {
        (self.sum_sq / self.points as f64).sqrt()
    }
}

/// The leave-one-out error across E2 at every pressure, over every slice of the effect axes
/// (a table that varies an effect: every value of it). Pressures with fewer than three
/// usable moduli are left out.
pub fn modulus_leave_one_out(lut: &Lut) -> Vec<ModulusInterpolationError> {
    let g = &lut.grid;
    let n = g.modulus_kpa.len();
    let slices = effect_slices(lut);
    let mut out = Vec::new();
    for (jp, &p) in g.pressure_kpa.iter().enumerate() {
        let mut tally = Tally::new();
        let mut slices_compared = 0;
        for &(stiffening, material, friction, thickness) in &slices {
            let curves: Vec<Option<&LutCurve>> = (0..n)
                .map(|m| {
                    lut.curve(g.flat_index(GridIndex {
                        stiffening,
                        material,
                        friction,
                        thickness,
                        pressure: jp,
                        modulus: m,
                    }))
                    .filter(|c| c.failure.is_none() && c.u_s_mm.len() >= 2)
                })
                .collect();
            let points_before = tally.points;
            for k in 1..n.saturating_sub(1) {
                let Some(left_out) = curves[k] else { continue };
                let neighbours: Vec<usize> =
                    [k.checked_sub(2), Some(k - 1), Some(k + 1), Some(k + 2)]
                        .into_iter()
                        .flatten()
                        .filter(|&j| j < n && curves[j].is_some())
                        .collect();
                if !(neighbours.contains(&(k - 1)) && neighbours.contains(&(k + 1))) {
                    continue;
                }
                let reach = neighbours
                    .iter()
                    .filter_map(|&j| curves[j].map(max_u_s))
                    .fold(max_u_s(left_out), f64::min);
                let xs: Vec<f64> = neighbours.iter().map(|&j| g.modulus_kpa[j].ln()).collect();
                for u in u_s_lattice(reach) {
                    let ys: Option<Vec<f64>> = neighbours
                        .iter()
                        .map(|&j| curves[j].and_then(|c| a_at(c, u)))
                        .collect();
                    if let (Some(ys), Some(truth)) = (ys, a_at(left_out, u)) {
                        let (pred, _) = pchip::eval(&xs, &ys, g.modulus_kpa[k].ln());
                        tally.add(pred, truth, g.modulus_kpa[k]);
                    }
                }
            }
            if tally.points > points_before {
                slices_compared += 1;
            }
        }
        if tally.points > 0 {
            out.push(ModulusInterpolationError {
                pressure_kpa: p,
                max_um: tally.max_um,
                rms_um: tally.rms_um(),
                worst_modulus_kpa: tally.worst_modulus_kpa,
                points: tally.points,
                slices: slices_compared,
            });
        }
    }
    out
}

/// The leave-one-out interpolation error in a at one left-out pressure node, over every
/// modulus node and every slice of the effect axes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PressureInterpolationError {
    /// The left-out pressure node (kPa).
    pub pressure_kpa: f64,
    /// Largest |prediction - stored a| over the moduli, u_s and slices (µm).
    pub max_um: f64,
    /// RMS over the same points (µm).
    pub rms_um: f64,
    /// The modulus where the largest difference sits (kPa).
    pub worst_modulus_kpa: f64,
    /// Points compared.
    pub points: usize,
    /// Slices of the effect axes compared.
    pub slices: usize,
}

/// The leave-one-out error across p_air: every inflated pressure node with inflated nodes on
/// both sides, left out and read from the remaining inflated nodes (the bracketing pair and
/// the outer neighbours that exist) at every modulus node, at u_s every [`U_S_STEP_MM`]
/// from [`U_S_MIN_MM`] that each curve involved reaches. The deflated node (p_air = 0) takes
/// no part, as in the table's own reads. Empty for a table with fewer than three inflated
/// pressures.
pub fn pressure_leave_one_out(lut: &Lut) -> Vec<PressureInterpolationError> {
    let g = &lut.grid;
    let inflated: Vec<usize> = (0..g.pressure_kpa.len())
        .filter(|&j| g.pressure_kpa[j] > 0.0)
        .collect();
    let slices = effect_slices(lut);
    let mut out = Vec::new();
    for left in 1..inflated.len().saturating_sub(1) {
        // the remaining inflated nodes, as grid indices and pressures
        let rest: Vec<usize> = inflated
            .iter()
            .copied()
            .filter(|&j| j != inflated[left])
            .collect();
        let xs: Vec<f64> = rest.iter().map(|&j| g.pressure_kpa[j]).collect();
        let p = g.pressure_kpa[inflated[left]];
        let k = left - 1;
        let weights = pressure_weights::hermite_weights(&xs, k, p, k >= 1, k + 2 < xs.len());
        let mut tally = Tally::new();
        let mut slices_compared = 0;
        for &(stiffening, material, friction, thickness) in &slices {
            let curve = |jp: usize, m: usize| {
                lut.curve(g.flat_index(GridIndex {
                    stiffening,
                    material,
                    friction,
                    thickness,
                    pressure: jp,
                    modulus: m,
                }))
                .filter(|c| c.failure.is_none() && c.u_s_mm.len() >= 2)
            };
            let points_before = tally.points;
            for m in 0..g.modulus_kpa.len() {
                let Some(left_out) = curve(inflated[left], m) else {
                    continue;
                };
                let used: Option<Vec<(&LutCurve, f64)>> = weights
                    .iter()
                    .map(|&(i, w)| curve(rest[i], m).map(|c| (c, w)))
                    .collect();
                let Some(used) = used else { continue };
                let reach = used
                    .iter()
                    .map(|&(c, _)| max_u_s(c))
                    .fold(max_u_s(left_out), f64::min);
                for u in u_s_lattice(reach) {
                    let pred: Option<f64> =
                        used.iter().map(|&(c, w)| a_at(c, u).map(|a| w * a)).sum();
                    if let (Some(pred), Some(truth)) = (pred, a_at(left_out, u)) {
                        tally.add(pred, truth, g.modulus_kpa[m]);
                    }
                }
            }
            if tally.points > points_before {
                slices_compared += 1;
            }
        }
        if tally.points > 0 {
            out.push(PressureInterpolationError {
                pressure_kpa: p,
                max_um: tally.max_um,
                rms_um: tally.rms_um(),
                worst_modulus_kpa: tally.worst_modulus_kpa,
                points: tally.points,
                slices: slices_compared,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lut::grid::LutGrid;

    /// Curve `index` at modulus `e`: a linear in ln E2 at every u_s (0..2 mm), plus `bump_mm`.
    fn linear_curve(index: usize, e: f64, bump_mm: f64) -> LutCurve {
        let u_s_mm: Vec<f64> = (0..=20).map(|i| 0.1 * i as f64).collect();
        LutCurve {
            index,
            failure: None,
            rest_volume_mm3: 1.0,
            inflated_volume_mm3: 1.0,
            inflation_apex_mm: 0.0,
            h_mm: u_s_mm.clone(),
            a_mm: u_s_mm
                .iter()
                .map(|u| 1.0 + u * (1.0 - 0.1 * e.ln()) + bump_mm)
                .collect(),
            load_n: vec![0.0; u_s_mm.len()],
            volume_mm3: vec![1.0; u_s_mm.len()],
            u_s_mm,
        }
    }

    /// A table whose a is linear in ln E2 at every u_s: PCHIP reproduces straight lines, so
    /// the leave-one-out error is zero to rounding; a bump of 4 um at one node shows up with
    /// its full size.
    #[test]
    fn zero_for_a_straight_line_in_ln_e_and_the_bump_where_it_is() {
        let grid = LutGrid::with_axes(
            "loo",
            LutGrid::tiny_grid().base,
            vec![10.0, 20.0, 40.0, 80.0, 160.0],
            vec![6.0],
        );
        let curve = |m: usize, bump_mm: f64| linear_curve(m, grid.modulus_kpa[m], bump_mm);
        let table = |bump_at: Option<usize>| Lut {
            grid: grid.clone(),
            fem_core_version: Lut::this_fem_core_version(),
            solver: "synthetic".into(),
            shard: None,
            contact_radius_error: None,
            edge_band: None,
            curves: (0..5)
                .map(|m| curve(m, if bump_at == Some(m) { 0.004 } else { 0.0 }))
                .collect(),
        };
        let clean = modulus_leave_one_out(&table(None));
        assert_eq!(clean.len(), 1);
        assert!(clean[0].max_um < 1e-9, "{clean:?}");
        // 3 interior nodes x u_s 0.2..2.0 mm every 0.02 mm
        assert_eq!(clean[0].points, 3 * 91);
        // Left out, the bumped node misses by the bump itself (4 um); its neighbours, read
        // through it, by about as much (PCHIP's slopes carry it): nothing hides it.
        let bumped = modulus_leave_one_out(&table(Some(2)));
        assert!(
            bumped[0].max_um >= 4.0 - 1e-9 && bumped[0].max_um < 5.0,
            "{bumped:?}"
        );
    }

    /// A table with an effect axis: every slice is compared, so a bump in the second slice
    /// only (not the first, which the figure used to read alone) is found.
    #[test]
    fn every_effect_slice_is_compared() {
        let mut grid = LutGrid::with_axes(
            "loo-slices",
            LutGrid::tiny_grid().base,
            vec![10.0, 20.0, 40.0, 80.0, 160.0],
            vec![6.0],
        );
        grid.effects.friction = vec![0.0, 0.4];
        let curves = (0..10)
            .map(|index| {
                let (slice, m) = (index / 5, index % 5);
                let bump_mm = if slice == 1 && m == 2 { 0.004 } else { 0.0 };
                linear_curve(index, grid.modulus_kpa[m], bump_mm)
            })
            .collect();
        let table = Lut {
            grid,
            fem_core_version: Lut::this_fem_core_version(),
            solver: "synthetic".into(),
            shard: None,
            contact_radius_error: None,
            edge_band: None,
            curves,
        };
        let errors = modulus_leave_one_out(&table);
        assert_eq!(errors.len(), 1);
        assert_eq!(errors[0].slices, 2, "{errors:?}");
        assert_eq!(errors[0].points, 2 * 3 * 91, "{errors:?}");
        assert!(
            errors[0].max_um >= 4.0 - 1e-9 && errors[0].max_um < 5.0,
            "{errors:?}"
        );
        // at the bumped node or a neighbour read through it (as in the test above)
        assert!(
            [20.0, 40.0, 80.0].contains(&errors[0].worst_modulus_kpa),
            "{errors:?}"
        );
    }

    /// Across p_air: a parabola in p_air is read exactly by the table's cubic (its slopes
    /// come from parabolas), so leaving a node out costs nothing, whatever the deflated
    /// node holds (it takes no part: here it is off by a millimetre); a 4 um bump at one
    /// inflated node shows up with its full size where that node is left out.
    #[test]
    fn across_pressure_zero_for_a_parabola_and_the_bump_where_it_is() {
        let pressures = vec![0.0, 6.0, 10.0, 15.0, 20.0, 30.0];
        let grid = LutGrid::with_axes(
            "loo-p",
            LutGrid::tiny_grid().base,
            vec![10.0, 100.0],
            pressures.clone(),
        );
        let table = |bump_at: Option<f64>| {
            let curves = (0..pressures.len() * 2)
                .map(|index| {
                    let (jp, m) = (index / 2, index % 2);
                    let p = pressures[jp];
                    let mut c = linear_curve(index, grid.modulus_kpa[m], 0.0);
                    let shift = if p == 0.0 {
                        1.0
                    } else {
                        1e-3 * (p - 0.02 * p * p) + if bump_at == Some(p) { 0.004 } else { 0.0 }
                    };
                    c.a_mm.iter_mut().for_each(|a| *a += shift);
                    c
                })
                .collect();
            Lut {
                grid: grid.clone(),
                fem_core_version: Lut::this_fem_core_version(),
                solver: "synthetic".into(),
                shard: None,
                contact_radius_error: None,
                edge_band: None,
                curves,
            }
        };
        let clean = pressure_leave_one_out(&table(None));
        let left_out: Vec<f64> = clean.iter().map(|e| e.pressure_kpa).collect();
        assert_eq!(left_out, [10.0, 15.0, 20.0]);
        for e in &clean {
            assert!(e.max_um < 1e-9, "{e:?}");
            // 2 moduli x u_s 0.2..2.0 mm every 0.02 mm
            assert_eq!(e.points, 2 * 91, "{e:?}");
        }
        let bumped = pressure_leave_one_out(&table(Some(15.0)));
        assert!(
            bumped[1].max_um >= 4.0 - 1e-9 && bumped[1].max_um < 4.0 + 1e-6,
            "{bumped:?}"
        );
    }
}
