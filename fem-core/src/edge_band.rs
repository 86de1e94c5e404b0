//! A band of fine elements that follows the contact edge along the curve.
//!
//! The contact pressure of the shell on the sample peaks near the edge (the wall's bending
//! carries load to the rim) and falls to zero over ~0.15 mm; where it falls is the contact
//! radius a. The production mesh (~0.1 mm node spacing) puts one or two nodes in that fall,
//! so its a scatters by tens of um from step to step (docs/fem-verification.md). A band of
//! 25 um elements around the edge ([`crate::problem::EdgeWindow`]) resolves it: halving
//! the band's elements again moves a by under a micrometre. The edge travels ~4 mm over a
//! curve, so the band moves with it: before a step whose predicted edge leaves the middle
//! of the band, the mesh is rebuilt with the band centred on that edge (placed at the
//! material points now at those radii), the converged state is
//! interpolated onto it ([`transfer_block`]: exact for the old mesh's quadratic fields
//! where the old elements are kept or subdivided) and the equilibrium at the same travel is
//! solved again before the step. The edge itself stays inside fine elements of both meshes,
//! so the contact state near it carries over. If no transfer converges and the edge has
//! reached the band's end, the travel so far is solved again from the start on the moved
//! mesh instead, and the curve goes on from there.
//!
//! Friction carries over too. Its regularised Coulomb law (`crate::contact`) makes the
//! tangential force a function of each slave's slip since a reference, its surface
//! coordinate at the last converged state, and nothing else: the moved mesh takes each of
//! its slaves' coordinates in the carried state as that reference, the re-solve rebuilds
//! the tangential tractions from slips of the law's regularisation length (0.4 um at 0.05
//! mm steps), and the re-solved state is the reference of the next step, as a converged
//! step's is. Friction's change of a and of the load is then closer to solves two mesh
//! levels finer than the production mesh's is (docs/fem-verification.md, "Friction in
//! the band").

use crate::mesh::Block;

/// How the band around the contact edge is meshed and moved.
#[derive(Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EdgeBand {
    /// Element size inside the band (mm).
    pub fine_size_mm: f64,
    /// Half-width of the band (mm, along the surfaces).
    pub half_width_mm: f64,
    /// Element size through the sample's top layer (mm).
    pub depth_size_mm: f64,
    /// The production mesh's two elements through the shell's wall outside the band
    /// ([`crate::problem::BAND_COARSE_MARGIN_MM`] beyond it), and its radial elements in
    /// the sample below the top layer ([`crate::problem::BAND_FINE_RADIAL_DEPTH_MM`]),
    /// joined to the band's finer ones by hanging nodes ([`crate::mesh::HangingNode`]):
    /// 28 % fewer equations, a within ~2.5 um of the band's on deformable samples, no
    /// reliable saving of time (docs/fem-verification.md, "Through the wall"). Otherwise
    /// the band's wall division runs along the whole shell and its radial elements through
    /// the whole depth.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub coarse_outside: bool,
}

/// The fields, `coarse_outside` only when set: the recorded solver descriptions of the
/// tables built before it existed stay those of the same band.
impl std::fmt::Debug for EdgeBand {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut d = f.debug_struct("EdgeBand");
        d.field("fine_size_mm", &self.fine_size_mm)
            .field("half_width_mm", &self.half_width_mm)
            .field("depth_size_mm", &self.depth_size_mm);
        if self.coarse_outside {
            d.field("coarse_outside", &true);
        }
        d.finish()
    }
}

/// Elements through the shell's 0.4 mm wall under the band. The production mesh's two
/// leave a 3-5 um low on 100-1000 kPa samples against sixteen; eight are within 0.7 um
/// of sixteen at 1000 kPa / 15 kPa (the stiffest sample the tables hold), for 1.2-2 times
/// the band's cost with two (docs/fem-verification.md, "Through the wall").
pub const CONVERGED_WALL_ELEMENTS: usize = 8;

/// Elements through the wall of a simulated truth one refinement beyond the tables'
/// converged settings ([`EdgeBand::FINER`]): twice [`CONVERGED_WALL_ELEMENTS`].
pub const FINER_WALL_ELEMENTS: usize = 16;

impl EdgeBand {
    /// 25 um elements over +-0.3 mm, 50 um into the sample's depth (see the convergence
    /// study in docs/fem-verification.md: 12.5 um elements, along the surfaces and into
    /// the depth, move a by under 1 um; 25 um depth elements cost 2.5 times the time for
    /// about 1.5 um more).
    pub const CONVERGED: Self = Self {
        fine_size_mm: 0.025,
        half_width_mm: 0.3,
        depth_size_mm: 0.05,
        coarse_outside: false,
    };

    /// [`EdgeBand::CONVERGED`] refined once along the surfaces (12.5 um elements): with
    /// [`FINER_WALL_ELEMENTS`] through the wall, the discretisation of a simulated truth
    /// that does not share the tables' ([`crate::Simulation::with_finer_edge_band`]). The
    /// converged settings' a differs from it by 1.0 um at most at 200 kPa / 6 kPa and by
    /// 1.4 um RMS, 2.95 um at most at 1000 kPa / 15 kPa (docs/fem-verification.md), for
    /// about four times the time.
    pub const FINER: Self = Self {
        fine_size_mm: 0.0125,
        ..Self::CONVERGED
    };

    /// The band's extent [lo, hi] (current radius, mm) for an edge expected at `a_mm`: from
    /// the axis while the edge is within three half-widths of it (the whole small contact
    /// zone fine: a band starting just inside a small contact leaves the pressure's
    /// build-up towards its rim in coarse elements, ~5 um off at a = 0.6 mm on a rigid
    /// sample), otherwise centred on the edge.
    pub fn extent(&self, a_mm: f64) -> [f64; 2] {
        let w = self.half_width_mm;
        if a_mm < 3.0 * w {
            [0.0, (a_mm + w).max(2.0 * w)]
        } else {
            [a_mm - w, a_mm + w]
        }
    }

    /// Whether a band of extent `band` still holds an edge expected at `a_mm` in its middle
    /// (at least half a half-width from either end; a band from the axis has no inner end).
    pub fn holds(&self, band: [f64; 2], a_mm: f64) -> bool {
        let margin = 0.5 * self.half_width_mm;
        a_mm <= band[1] - margin && (band[0] == 0.0 || a_mm >= band[0] + margin)
    }
}

/// 1D quadratic Lagrange weights of the element of the node coordinates `c` (element e
/// spans nodes 2e, 2e + 1, 2e + 2, mid nodes anywhere inside) that contains x; returns the
/// element's first node and the weights. Outside the range the end element extrapolates.
pub fn quadratic_weights(c: &[f64], x: f64) -> (usize, [f64; 3]) {
    let n_el = (c.len() - 1) / 2;
    let (mut lo, mut hi) = (0, n_el);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if c[2 * mid + 2] < x {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    let i = 2 * lo.min(n_el - 1);
    let (c0, c1, c2) = (c[i], c[i + 1], c[i + 2]);
    (
        i,
        [
            (x - c1) * (x - c2) / ((c0 - c1) * (c0 - c2)),
            (x - c0) * (x - c2) / ((c1 - c0) * (c1 - c2)),
            (x - c0) * (x - c1) / ((c2 - c0) * (c2 - c1)),
        ],
    )
}

/// A structured block with the grid coordinates of its nodes along each direction (node
/// (i, j) is at (`along_1[i]`, `along_2[j]`) in a parametrisation in which the block's
/// elements are tensor-product quadratic).
#[derive(Debug, Clone, Copy)]
pub struct GridBlock<'a> {
    pub block: &'a Block,
    pub along_1: &'a [f64],
    pub along_2: &'a [f64],
}

/// Interpolate the nodal vector field `u_old` (2 dofs per node) of the block `old` onto the
/// nodes of the block `new` of the same body, writing them into `u_new`.
pub fn transfer_block(old: &GridBlock<'_>, u_old: &[f64], new: &GridBlock<'_>, u_new: &mut [f64]) {
    for (j, &x2) in new.along_2.iter().enumerate() {
        let (j0, w2) = quadratic_weights(old.along_2, x2);
        for (i, &x1) in new.along_1.iter().enumerate() {
            let (i0, w1) = quadratic_weights(old.along_1, x1);
            let mut value = [0.0; 2];
            for (b, &wb) in w2.iter().enumerate() {
                for (a, &wa) in w1.iter().enumerate() {
                    let n = old.block.node(i0 + a, j0 + b);
                    value[0] += wa * wb * u_old[2 * n];
                    value[1] += wa * wb * u_old[2 * n + 1];
                }
            }
            let n = new.block.node(i, j);
            u_new[2 * n] = value[0];
            u_new[2 * n + 1] = value[1];
        }
    }
}

/// Linear interpolation of the samples (x_k, y_k) (x increasing) at x, constant beyond the
/// ends.
pub fn interpolate_linear(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    let k = xs.partition_point(|&v| v <= x);
    if k == 0 {
        return ys[0];
    }
    if k >= xs.len() {
        return ys[xs.len() - 1];
    }
    let t = (x - xs[k - 1]) / (xs[k] - xs[k - 1]);
    ys[k - 1] + t * (ys[k] - ys[k - 1])
}

#[cfg(test)]
// grid loops index several arrays at once, as the formulas do
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;

    #[test]
    fn quadratic_weights_reproduce_quadratics_on_graded_nodes() {
        // three elements of unequal size
        let c = [0.0, 0.5, 1.0, 1.25, 1.5, 2.25, 3.0];
        let f = |x: f64| 2.0 - x + 0.7 * x * x;
        for x in [0.0, 0.3, 1.0, 1.1, 1.49, 2.0, 3.0] {
            let (i, w) = quadratic_weights(&c, x);
            let v: f64 = (0..3).map(|a| w[a] * f(c[i + a])).sum();
            assert!((v - f(x)).abs() < 1e-12, "x = {x}: {v} vs {}", f(x));
            assert!(c[i] <= x + 1e-12 && x <= c[i + 2] + 1e-12);
        }
    }

    #[test]
    fn transfer_is_exact_for_a_biquadratic_field() {
        let (old_1, old_2) = ([0.0, 0.5, 1.0, 1.5, 2.0], [0.0, 0.1, 0.2]);
        let (new_1, new_2) = (
            [0.0, 0.2, 0.4, 0.7, 1.0, 1.6, 2.0],
            [0.0, 0.05, 0.1, 0.15, 0.2],
        );
        let old_block = Block {
            node_offset: 0,
            n1: 5,
            n2: 3,
        };
        let new_block = Block {
            node_offset: 3,
            n1: 7,
            n2: 5,
        };
        let f = |x: f64, y: f64| [x * x - 3.0 * y, 1.0 + x * y + y * y];
        let mut u_old = vec![0.0; 30];
        for j in 0..3 {
            for i in 0..5 {
                let n = old_block.node(i, j);
                [u_old[2 * n], u_old[2 * n + 1]] = f(old_1[i], old_2[j]);
            }
        }
        let mut u_new = vec![0.0; 2 * (3 + 35)];
        let old = GridBlock {
            block: &old_block,
            along_1: &old_1,
            along_2: &old_2,
        };
        let new = GridBlock {
            block: &new_block,
            along_1: &new_1,
            along_2: &new_2,
        };
        transfer_block(&old, &u_old, &new, &mut u_new);
        for j in 0..5 {
            for i in 0..7 {
                let n = new_block.node(i, j);
                let v = f(new_1[i], new_2[j]);
                assert!((u_new[2 * n] - v[0]).abs() < 1e-12);
                assert!((u_new[2 * n + 1] - v[1]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn the_band_starts_at_the_axis_for_small_contacts_and_follows_the_edge() {
        let band = EdgeBand::CONVERGED;
        assert_eq!(band.extent(0.1), [0.0, 0.6]);
        assert_eq!(band.extent(0.8), [0.0, 1.1]);
        let e = band.extent(2.0);
        assert!((e[0] - 1.7).abs() < 1e-12 && (e[1] - 2.3).abs() < 1e-12);
        assert!(band.holds(e, 2.0) && band.holds(e, 2.14) && band.holds(e, 1.86));
        assert!(!band.holds(e, 2.16) && !band.holds(e, 1.84));
        assert!(band.holds([0.0, 0.6], 0.0));
    }

    #[test]
    fn linear_interpolation_and_its_ends() {
        let (xs, ys) = ([0.0, 1.0, 3.0], [1.0, 3.0, 7.0]);
        assert_eq!(interpolate_linear(&xs, &ys, -1.0), 1.0);
        assert_eq!(interpolate_linear(&xs, &ys, 2.0), 5.0);
        assert_eq!(interpolate_linear(&xs, &ys, 9.0), 7.0);
    }
}
