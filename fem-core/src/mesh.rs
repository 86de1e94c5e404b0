//! Structured, mapped Q9 meshes of the two bodies in the (r, z) half-plane.
//!
//! Coordinates: the origin is the centre of the undeformed hemisphere, z points up (towards
//! the tube), so the shell's outer apex is at (0, -R1) and the sample lies below it.
//!
//! - Shell: a (s, t) mapped grid; s runs along the mid-surface from the apex over the
//!   hemisphere (uniform in the polar angle) and up the cylindrical skirt, t runs through the
//!   wall from the inner to the outer surface. Nodes are placed on the exact geometry.
//! - Sample: a rectangle r in [0, R_s], z in [z_top - T, z_top], uniform near the axis and the
//!   top surface (the contact zone) and geometrically graded away from it.

// Index loops mirror the tensor-index equations of the numerical kernels.
#![allow(clippy::needless_range_loop)]

use crate::shape::q9;

/// One Q9 element: global node numbers in tensor order (see [`crate::shape`]) and its body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MeshElement {
    pub nodes: [usize; 9],
    pub body: usize,
}

/// Nodes (reference coordinates, mm) and elements of all bodies.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    pub nodes: Vec<[f64; 2]>,
    pub elements: Vec<MeshElement>,
    /// Nodes whose displacement follows others' (see [`HangingNode`]).
    pub hanging: Vec<HangingNode>,
}

/// A node of a fine element that lies on the edge of a coarser neighbour (or inside a
/// coarse element, where no element uses it): its displacement is the coarse element's
/// quadratic interpolation of its masters' along that edge, `u = sum w_k u_k`, which keeps
/// the displacement field continuous across the change of element size (the constrained
/// fine edge reproduces the coarse edge's quadratic exactly).
#[derive(Debug, Clone, PartialEq)]
pub struct HangingNode {
    pub node: usize,
    /// (master node, weight); the weights sum to one, the masters are never hanging.
    pub masters: Vec<(usize, f64)>,
}

/// Where a structured block's elements are coarser than its node grid: along the
/// coarsened `direction`, the element lines (the elements sharing one index across it)
/// that are not `fine` merge the fine elements of each of `groups` into one element
/// (uniform fine elements inside a group, so that its middle node is at its middle).
#[derive(Debug, Clone, PartialEq)]
pub struct Coarsening {
    /// The grid direction along which elements are merged.
    pub direction: GridDirection,
    /// Per element line across `direction`: every fine element kept.
    pub fine: Vec<bool>,
    /// Fine elements per coarse element along `direction`, in order (their sum is the
    /// block's element count in that direction).
    pub groups: Vec<usize>,
}

/// A direction of a structured block's grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GridDirection {
    First,
    Second,
}

/// A structured block of (2 nx_el + 1) x (2 ny_el + 1) nodes inside a [`Mesh`].
#[derive(Debug, Clone, Copy)]
pub struct Block {
    pub node_offset: usize,
    /// Nodes along the first grid direction.
    pub n1: usize,
    /// Nodes along the second grid direction.
    pub n2: usize,
}

impl Block {
    /// Global node number of grid node (i, j).
    pub fn node(&self, i: usize, j: usize) -> usize {
        self.node_offset + j * self.n1 + i
    }
}

impl Mesh {
    /// Append a structured block whose node (i, j) is at `position(i, j)`; elements are
    /// oriented so that their Jacobian is positive.
    pub fn add_block(
        &mut self,
        n1: usize,
        n2: usize,
        body: usize,
        position: impl Fn(usize, usize) -> [f64; 2],
    ) -> Block {
        let block = self.add_grid_nodes(n1, n2, position);
        for ej in 0..(n2 - 1) / 2 {
            for ei in 0..(n1 - 1) / 2 {
                let mut nodes = [0; 9];
                for jj in 0..3 {
                    for ii in 0..3 {
                        nodes[3 * jj + ii] = block.node(2 * ei + ii, 2 * ej + jj);
                    }
                }
                self.push_oriented(nodes, body);
            }
        }
        block
    }

    /// [`Self::add_block`] with the coarser elements of `coarsening` outside its fine
    /// element lines; the grid nodes that no coarse element has as its own and that lie on
    /// or inside one are appended to [`Mesh::hanging`], constrained to that element's
    /// quadratic interpolation along the coarsened direction, at the parent coordinate the
    /// node's grid position `along` (its coordinate along that direction) gives.
    pub fn add_block_coarsened(
        &mut self,
        n1: usize,
        n2: usize,
        body: usize,
        position: impl Fn(usize, usize) -> [f64; 2],
        along: &[f64],
        coarsening: &Coarsening,
    ) -> Block {
        let block = self.add_grid_nodes(n1, n2, position);
        // (index p across the coarsened direction, index q along it) -> grid node
        let first = coarsening.direction == GridDirection::First;
        let at = |p: usize, q: usize| {
            if first {
                block.node(q, p)
            } else {
                block.node(p, q)
            }
        };
        let n_lines = if first { n2 } else { n1 };
        let mut hanging = vec![false; n1 * n2];
        for e in 0..(n_lines - 1) / 2 {
            let fine = coarsening.fine.get(e).copied().unwrap_or(true);
            let mut start = 0;
            for &count in &coarsening.groups {
                let spans: Vec<(usize, usize)> = if fine {
                    (0..count).map(|k| (2 * (start + k), 1)).collect()
                } else {
                    vec![(2 * start, count)]
                };
                for (q0, step) in spans {
                    let mut nodes = [0; 9];
                    for b in 0..3 {
                        for a in 0..3 {
                            // local node 3 b + a: a along the first grid direction
                            let (pp, qq) = if first { (b, a) } else { (a, b) };
                            nodes[3 * b + a] = at(2 * e + pp, q0 + qq * step);
                        }
                    }
                    self.push_oriented(nodes, body);
                }
                if !fine && count > 1 {
                    let qs = [2 * start, 2 * start + count, 2 * (start + count)];
                    let (x0, x2) = (along[qs[0]], along[qs[2]]);
                    assert_exact_group(along, qs);
                    for p in 2 * e..=2 * e + 2 {
                        for q in qs[0] + 1..qs[2] {
                            let node = at(p, q);
                            if q == qs[1] || hanging[node - block.node_offset] {
                                continue;
                            }
                            hanging[node - block.node_offset] = true;
                            let eta = 2.0 * (along[q] - x0) / (x2 - x0) - 1.0;
                            let (w, _) = crate::shape::line3(eta);
                            self.hanging.push(HangingNode {
                                node,
                                masters: (0..3).map(|k| (at(p, qs[k]), w[k])).collect(),
                            });
                        }
                    }
                }
                start += count;
            }
        }
        block
    }

    /// Append the nodes of an n1 x n2 grid, node (i, j) at `position(i, j)`.
    fn add_grid_nodes(
        &mut self,
        n1: usize,
        n2: usize,
        position: impl Fn(usize, usize) -> [f64; 2],
    ) -> Block {
        let block = Block {
            node_offset: self.nodes.len(),
            n1,
            n2,
        };
        for j in 0..n2 {
            for i in 0..n1 {
                self.nodes.push(position(i, j));
            }
        }
        block
    }

    /// Append an element, its first parent direction mirrored if its Jacobian would be
    /// negative.
    fn push_oriented(&mut self, mut nodes: [usize; 9], body: usize) {
        if self.parent_jacobian(&nodes) < 0.0 {
            for jj in 0..3 {
                nodes.swap(3 * jj, 3 * jj + 2);
            }
        }
        self.elements.push(MeshElement { nodes, body });
    }

    fn parent_jacobian(&self, nodes: &[usize; 9]) -> f64 {
        let (_, dn) = q9(0.0, 0.0);
        let mut jac = [[0.0; 2]; 2];
        for (a, &n) in nodes.iter().enumerate() {
            for r in 0..2 {
                for c in 0..2 {
                    jac[r][c] += self.nodes[n][r] * dn[a][c];
                }
            }
        }
        jac[0][0] * jac[1][1] - jac[0][1] * jac[1][0]
    }

    /// Reference coordinates of an element's nodes.
    pub fn element_coordinates(&self, element: &MeshElement) -> [[f64; 2]; 9] {
        element.nodes.map(|n| self.nodes[n])
    }
}

/// Shell geometry: hemisphere plus cylindrical skirt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShellGeometry {
    pub inner_radius_mm: f64,
    pub outer_radius_mm: f64,
    /// Length of the cylindrical skirt above the equator (0: hemisphere only).
    pub skirt_length_mm: f64,
}

/// Element counts of the shell mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShellDivisions {
    /// Elements along the hemisphere (apex to equator).
    pub arc: usize,
    /// Elements along the skirt.
    pub skirt: usize,
    /// Elements through the wall.
    pub thickness: usize,
}

/// Node sets of the shell needed by loads and boundary conditions.
#[derive(Debug, Clone)]
pub struct ShellMesh {
    pub block: Block,
    /// Inner-surface nodes of the hemisphere from the apex to the equator.
    pub inner_surface: Vec<usize>,
    /// Outer-surface nodes of the hemisphere from the apex to the equator (contact side).
    pub outer_surface: Vec<usize>,
    /// Nodes on the symmetry axis (apex line through the wall).
    pub axis: Vec<usize>,
    /// Inner skirt nodes (clamped to the tube), equator included; empty without a skirt.
    pub clamped: Vec<usize>,
    /// Nodes on the equator plane z = 0 (through the wall).
    pub equator: Vec<usize>,
    /// Inner apex node (paper eq. 6).
    pub inner_apex: usize,
    /// Outer apex node.
    pub outer_apex: usize,
}

/// Local refinement of the hemisphere along the arc where the contact edge travels: from the
/// apex to the polar angle `fine_angle_rad` the elements are `refinement` times shorter than
/// the uniform ones; beyond it they grow geometrically (ratio `growth`) back to the uniform
/// size. `refinement` 1 is the uniform arc.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcGrading {
    pub refinement: usize,
    pub fine_angle_rad: f64,
    pub growth: f64,
}

impl ArcGrading {
    /// The uniform arc.
    pub const UNIFORM: Self = Self {
        refinement: 1,
        fine_angle_rad: 0.0,
        growth: 1.3,
    };

    /// Element edges (polar angles, apex to equator) for `arc` uniform elements.
    pub fn edges(&self, arc: usize) -> Vec<f64> {
        let quarter = std::f64::consts::FRAC_PI_2;
        let coarse = quarter / arc as f64;
        if self.refinement <= 1 || self.fine_angle_rad <= 0.0 {
            return (0..=arc).map(|k| quarter * k as f64 / arc as f64).collect();
        }
        let fine = coarse / self.refinement as f64;
        graded_edges_capped(quarter, fine, self.fine_angle_rad, self.growth, coarse)
    }
}

/// Build the shell block into `mesh` as body `body` (uniform along the arc).
pub fn add_shell(
    mesh: &mut Mesh,
    geometry: &ShellGeometry,
    div: &ShellDivisions,
    body: usize,
) -> ShellMesh {
    add_shell_graded(mesh, geometry, div, &ArcGrading::UNIFORM, body)
}

/// Build the shell block into `mesh` as body `body`, its arc graded by `grading`
/// (`div.arc` counts the uniform elements the grading refines).
pub fn add_shell_graded(
    mesh: &mut Mesh,
    geometry: &ShellGeometry,
    div: &ShellDivisions,
    grading: &ArcGrading,
    body: usize,
) -> ShellMesh {
    add_shell_with_arc_edges(mesh, geometry, div, &grading.edges(div.arc), body)
}

/// Build the shell block into `mesh` as body `body`, with the element edges along the
/// hemisphere given as polar angles from 0 (apex) to pi/2 (equator).
pub fn add_shell_with_arc_edges(
    mesh: &mut Mesh,
    geometry: &ShellGeometry,
    div: &ShellDivisions,
    arc_edges: &[f64],
    body: usize,
) -> ShellMesh {
    add_shell_coarsened(mesh, geometry, div, arc_edges, None, body)
}

/// [`add_shell_with_arc_edges`] with the coarser elements of `coarsening` (the first grid
/// direction runs along the arc and the skirt, the second through the wall from the inner
/// surface; merged groups need equal fine elements, in polar angle along the arc).
pub fn add_shell_coarsened(
    mesh: &mut Mesh,
    geometry: &ShellGeometry,
    div: &ShellDivisions,
    arc_edges: &[f64],
    coarsening: Option<&Coarsening>,
    body: usize,
) -> ShellMesh {
    let phis = with_midpoints(arc_edges);
    let arc = (phis.len() - 1) / 2;
    let n_arc_nodes = 2 * arc + 1;
    let n1 = n_arc_nodes + 2 * div.skirt;
    let n2 = 2 * div.thickness + 1;
    let g = *geometry;
    let skirt = div.skirt;
    let position = |i: usize, j: usize| {
        let t = g.inner_radius_mm
            + (g.outer_radius_mm - g.inner_radius_mm) * j as f64 / (n2 - 1) as f64;
        if i < n_arc_nodes {
            let phi = phis[i];
            if i == 0 {
                [0.0, -t]
            } else {
                [t * phi.sin(), -t * phi.cos()]
            }
        } else {
            let k = i - (n_arc_nodes - 1);
            [t, g.skirt_length_mm * k as f64 / (2 * skirt) as f64]
        }
    };
    let block = match coarsening {
        None => mesh.add_block(n1, n2, body, position),
        Some(c) => {
            // the grid coordinates the elements are quadratic in: along the arc the polar
            // angle, then the skirt's node index (uniform); through the wall the node index
            let along: Vec<f64> = match c.direction {
                GridDirection::First => (0..n1)
                    .map(|i| {
                        phis.get(i).copied().unwrap_or_else(|| {
                            std::f64::consts::FRAC_PI_2 + (i + 1 - n_arc_nodes) as f64
                        })
                    })
                    .collect(),
                GridDirection::Second => (0..n2).map(|j| j as f64).collect(),
            };
            mesh.add_block_coarsened(n1, n2, body, position, &along, c)
        }
    };
    let inner_surface = (0..n_arc_nodes).map(|i| block.node(i, 0)).collect();
    let outer_surface = (0..n_arc_nodes).map(|i| block.node(i, n2 - 1)).collect();
    let axis = (0..n2).map(|j| block.node(0, j)).collect();
    let clamped = if skirt > 0 {
        (n_arc_nodes - 1..n1).map(|i| block.node(i, 0)).collect()
    } else {
        Vec::new()
    };
    let equator = (0..n2).map(|j| block.node(n_arc_nodes - 1, j)).collect();
    ShellMesh {
        block,
        inner_surface,
        outer_surface,
        axis,
        clamped,
        equator,
        inner_apex: block.node(0, 0),
        outer_apex: block.node(0, n2 - 1),
    }
}

/// Sample geometry and grading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleGeometry {
    pub radius_mm: f64,
    pub thickness_mm: f64,
    /// z of the top surface in the global frame.
    pub top_z_mm: f64,
}

/// Element sizes of the sample mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleGrading {
    /// Radial element size in the contact zone (near the axis, at the top): the spacing of
    /// the contact surface's nodes.
    pub fine_size_mm: f64,
    /// Element size through the uniformly meshed layer under the top surface.
    pub fine_depth_size_mm: f64,
    /// Radius of the uniformly meshed contact zone.
    pub fine_radius_mm: f64,
    /// Depth of the uniformly meshed layer under the top surface.
    pub fine_depth_mm: f64,
    /// Geometric growth ratio of element sizes outside the fine zone.
    pub growth: f64,
}

impl SampleGrading {
    /// The sample's element edges: radii from the axis outwards, depths below the top.
    pub fn edges(&self, geometry: &SampleGeometry) -> (Vec<f64>, Vec<f64>) {
        (
            graded_edges(
                geometry.radius_mm,
                self.fine_size_mm,
                self.fine_radius_mm,
                self.growth,
            ),
            graded_edges(
                geometry.thickness_mm,
                self.fine_depth_size_mm,
                self.fine_depth_mm,
                self.growth,
            ),
        )
    }
}

/// Node sets of the sample.
#[derive(Debug, Clone)]
pub struct SampleMesh {
    pub block: Block,
    /// Top-surface nodes ordered by increasing r (the contact surface).
    pub top: Vec<usize>,
    pub axis: Vec<usize>,
    /// Bottom nodes (bonded to the rigid base).
    pub bottom: Vec<usize>,
}

/// Element boundaries on [0, length]: uniform of size <= `fine` up to `fine_len`, then
/// sizes growing geometrically by `growth`; the last element is merged if it would be tiny.
pub fn graded_edges(length: f64, fine: f64, fine_len: f64, growth: f64) -> Vec<f64> {
    let fine_len = fine_len.min(length);
    let n_fine = ((fine_len / fine) - 1e-9).ceil().max(1.0) as usize;
    let size = fine_len / n_fine as f64;
    let mut edges: Vec<f64> = (0..=n_fine).map(|k| k as f64 * size).collect();
    let mut h = size;
    let mut x = fine_len;
    while x < length - 1e-12 {
        h *= growth;
        if x + h * (1.0 + 0.5 * growth) >= length {
            edges.push(length);
            break;
        }
        x += h;
        edges.push(x);
    }
    edges
}

/// Like [`graded_edges`], but the growing sizes stop at `max_size` and continue uniformly
/// (the last one stretched or merged so that the interval is covered exactly).
pub fn graded_edges_capped(
    length: f64,
    fine: f64,
    fine_len: f64,
    growth: f64,
    max_size: f64,
) -> Vec<f64> {
    let fine_len = fine_len.min(length);
    let n_fine = ((fine_len / fine) - 1e-9).ceil().max(1.0) as usize;
    let size = fine_len / n_fine as f64;
    let edges: Vec<f64> = (0..=n_fine).map(|k| k as f64 * size).collect();
    let mut h = size;
    march(length, edges, |_| {
        h = (h * growth).min(max_size);
        h
    })
}

/// Continue the element edges `edges` to `length` with elements of size `next(x)` from the
/// last edge x; the last element is stretched to the end, or merged with the one before,
/// when less than half an element would be left.
fn march(length: f64, mut edges: Vec<f64>, mut next: impl FnMut(f64) -> f64) -> Vec<f64> {
    let mut x = edges.last().copied().unwrap_or(0.0);
    while x < length - 1e-12 {
        let h = next(x);
        if x + 1.5 * h >= length {
            edges.push(length);
            break;
        }
        x += h;
        edges.push(x);
    }
    edges
}

/// Element boundaries on [0, length] from a size field: the element starting at x has the
/// size `size(y)` at its far end y (solved by fixed-point iteration, so a size that shrinks
/// towards a refined window is reached before the window, not overshot); the last element
/// is merged if it would be under half its size.
fn edges_from_size_field(length: f64, size: impl Fn(f64) -> f64) -> Vec<f64> {
    march(length, vec![0.0], |x| {
        let mut h = size(x);
        for _ in 0..30 {
            // the smallest size over the element (sampled), so a window inside it counts
            let h_new = (0..=8)
                .map(|i| size(x + h * i as f64 / 8.0))
                .fold(f64::INFINITY, f64::min);
            if (h_new - h).abs() <= 1e-12 * h {
                break;
            }
            h = h_new;
        }
        h
    })
}

/// A size field that is `fine` inside [lo, hi] and grows geometrically by `growth` per
/// element away from it (size = fine + (growth - 1) distance, the sizes of a geometric
/// progression), never above `coarse(x)`.
fn window_size(
    x: f64,
    lo: f64,
    hi: f64,
    fine: f64,
    growth: f64,
    coarse: impl Fn(f64) -> f64,
) -> f64 {
    let distance = (lo - x).max(x - hi).max(0.0);
    (fine + (growth - 1.0) * distance).min(coarse(x))
}

/// The element edges `base` (increasing) with the elements over [lo, hi] replaced by ones
/// of size `fine`, growing by `growth` per element back to the base sizes: only the base
/// elements within the transition's reach are replaced, the others are kept as they are
/// (so fields of the base mesh transfer exactly outside the refined stretch).
pub fn refined_edges(base: &[f64], lo: f64, hi: f64, fine: f64, growth: f64) -> Vec<f64> {
    let base_size = |y: f64| {
        let i = base.partition_point(|&e| e <= y).clamp(1, base.len() - 1);
        base[i] - base[i - 1]
    };
    // how far the sizes take to grow back to the base elements' at either end
    let reach = |coarse: f64| (coarse - fine).max(0.0) / (growth - 1.0) + coarse;
    let first = base
        .partition_point(|&e| e <= lo - reach(base_size(lo)))
        .saturating_sub(1);
    let last = base
        .partition_point(|&e| e < hi + reach(base_size(hi)))
        .min(base.len() - 1);
    let (start, end) = (base[first], base[last]);
    let stretch = edges_from_size_field(end - start, |x| {
        window_size(x + start, lo, hi, fine, growth, base_size)
    });
    let mut edges = base[..first].to_vec();
    edges.extend(stretch.iter().map(|x| x + start));
    edges.extend_from_slice(&base[last + 1..]);
    edges
}

/// Node positions (element edges plus mid points) from element edges.
fn with_midpoints(edges: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(2 * edges.len() - 1);
    for w in edges.windows(2) {
        out.push(w[0]);
        out.push(0.5 * (w[0] + w[1]));
    }
    if let Some(&last) = edges.last() {
        out.push(last);
    }
    out
}

/// Build the sample block into `mesh` as body `body`.
pub fn add_sample(
    mesh: &mut Mesh,
    geometry: &SampleGeometry,
    grading: &SampleGrading,
    body: usize,
) -> SampleMesh {
    let (r_edges, depth_edges) = grading.edges(geometry);
    add_sample_with_edges(mesh, geometry, &r_edges, &depth_edges, body)
}

/// Build the sample block into `mesh` as body `body` from its element edges: radii from the
/// axis outwards, depths below the top surface.
pub fn add_sample_with_edges(
    mesh: &mut Mesh,
    geometry: &SampleGeometry,
    r_edges: &[f64],
    depth_edges: &[f64],
    body: usize,
) -> SampleMesh {
    add_sample_coarsened(mesh, geometry, r_edges, depth_edges, None, body)
}

/// [`add_sample_with_edges`] with the coarser elements of `coarsening` (the first grid
/// direction runs radially from the axis, the second from the bottom up).
pub fn add_sample_coarsened(
    mesh: &mut Mesh,
    geometry: &SampleGeometry,
    r_edges: &[f64],
    depth_edges: &[f64],
    coarsening: Option<&Coarsening>,
    body: usize,
) -> SampleMesh {
    let r_nodes = with_midpoints(r_edges);
    // depth below the top surface, then ordered bottom -> top
    let mut z_nodes: Vec<f64> = with_midpoints(depth_edges)
        .into_iter()
        .map(|d| geometry.top_z_mm - d)
        .collect();
    z_nodes.reverse();
    let n1 = r_nodes.len();
    let n2 = z_nodes.len();
    let position = |i: usize, j: usize| [r_nodes[i], z_nodes[j]];
    let block = match coarsening {
        None => mesh.add_block(n1, n2, body, position),
        Some(c) => {
            let along = match c.direction {
                GridDirection::First => &r_nodes,
                GridDirection::Second => &z_nodes,
            };
            mesh.add_block_coarsened(n1, n2, body, position, along, c)
        }
    };
    SampleMesh {
        block,
        top: (0..n1).map(|i| block.node(i, n2 - 1)).collect(),
        axis: (0..n2).map(|j| block.node(0, j)).collect(),
        bottom: (0..n1).map(|i| block.node(i, 0)).collect(),
    }
}

/// The hanging constraints of a merged group `qs` (first, middle and last grid index along
/// the coarsened direction) are exact only if the coarse element's middle node lies at the
/// middle of its ends and every fine element inside it has its middle node at its middle,
/// in the coordinate `along` the elements are quadratic in: each fine edge is then an
/// affine piece of the coarse edge, which reproduces its quadratic. A layout that breaks
/// this would give inexact constraint weights silently, so it is refused here (the callers
/// build the groups themselves: this is a broken invariant, not bad input).
fn assert_exact_group(along: &[f64], qs: [usize; 3]) {
    let (x0, x2) = (along[qs[0]], along[qs[2]]);
    // round-off of the callers' coordinates (polar angles, radii) is ~1e-15 of the group;
    // 1e-9 of it moves a hanging node's weight by no more than that
    let tol = 1e-9 * (x2 - x0).abs();
    let middle_ok = |a: f64, m: f64, b: f64| (m - 0.5 * (a + b)).abs() <= tol;
    assert!(
        middle_ok(x0, along[qs[1]], x2),
        "merged group at grid index {}..{}: its middle node ({}) is not at the middle of \
         {x0} and {x2}; merged groups need fine elements of equal size",
        qs[0],
        qs[2],
        along[qs[1]]
    );
    for q in (qs[0]..qs[2]).step_by(2) {
        assert!(
            middle_ok(along[q], along[q + 1], along[q + 2]),
            "merged group at grid index {}..{}: the fine element at {q} has its middle node \
             off its middle",
            qs[0],
            qs[2]
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn graded_edges_cover_the_interval_monotonically() {
        let e = graded_edges(45.0, 0.1, 4.5, 1.3);
        assert_eq!(e[0], 0.0);
        assert!((e[e.len() - 1] - 45.0).abs() < 1e-12);
        assert!(e.windows(2).all(|w| w[1] > w[0]));
        assert!((e[1] - 0.1).abs() < 1e-12);
    }

    #[test]
    fn a_refined_stretch_keeps_the_base_elements_beyond_its_reach() {
        let base = graded_edges(45.0, 0.2, 4.5, 1.3);
        let e = refined_edges(&base, 1.7, 2.3, 0.025, 1.3);
        assert_eq!(e[0], 0.0);
        assert!((e[e.len() - 1] - 45.0).abs() < 1e-12);
        assert!(e.windows(2).all(|w| w[1] > w[0]));
        // inside the stretch: elements of the fine size (the last one before the growth
        // may be stretched by up to half)
        let inside: Vec<f64> = e
            .windows(2)
            .filter(|w| w[0] >= 1.7 && w[1] <= 2.3)
            .map(|w| w[1] - w[0])
            .collect();
        assert!(inside.len() >= 20);
        assert!(inside.iter().all(|&h| h <= 0.025 * 1.5 + 1e-12));
        // neighbours grow by at most the growth ratio (1.5 at a merged last element)
        assert!(e.windows(3).all(|w| {
            let (h0, h1) = (w[1] - w[0], w[2] - w[1]);
            h1 / h0 <= 1.5 + 1e-9 && h0 / h1 <= 1.5 + 1e-9
        }));
        // beyond the growth's reach ((0.2 - 0.025) / 0.3 + 0.2 = 0.78 mm) the base edges
        // are kept exactly
        for kept in base
            .iter()
            .filter(|&&b| !(1.7 - 0.8..=2.3 + 0.8).contains(&b))
        {
            assert!(e.contains(kept), "base edge {kept} kept");
        }
    }

    #[test]
    #[should_panic(expected = "merged groups need fine elements of equal size")]
    fn a_merged_group_of_unequal_fine_elements_is_refused() {
        // the second group merges fine elements of 0.2 and 0.4: its coarse middle node
        // (0.6) is not at the middle of 0.4 and 1.2, so its hanging weights would be inexact
        let x = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.9, 1.2];
        let coarsening = Coarsening {
            direction: GridDirection::First,
            fine: vec![true, false, false, false],
            groups: vec![2, 2],
        };
        Mesh::default().add_block_coarsened(9, 9, 0, |i, j| [1.0 + x[i], x[j]], &x, &coarsening);
    }

    #[test]
    #[should_panic(expected = "has its middle node off its middle")]
    fn a_fine_element_whose_middle_node_is_off_its_middle_is_refused() {
        // one merged group of two fine elements: the coarse middle node (0.2) is at the
        // middle of 0 and 0.4, but the first fine element's middle node is at 0.15, not 0.1
        let x = [0.0, 0.15, 0.2, 0.3, 0.4];
        let coarsening = Coarsening {
            direction: GridDirection::First,
            fine: vec![true, false],
            groups: vec![2],
        };
        Mesh::default().add_block_coarsened(5, 5, 0, |i, j| [1.0 + x[i], x[j]], &x, &coarsening);
    }

    #[test]
    fn hanging_nodes_interpolate_quadratics_along_either_direction() {
        // a 4 x 4 element block, coarse outside its first element line, groups of 2 and 2
        // merged, the groups of unequal size (uniform inside each, as a merged element's
        // middle node must be at its middle); every hanging node must carry a field
        // quadratic in the coarsened coordinate exactly (its coarse element's edge), and
        // its masters must be nodes no constraint moves
        let x1 = [0.0, 0.1, 0.2, 0.3, 0.4, 0.6, 0.8, 1.0, 1.2];
        let x2 = [0.0, 0.05, 0.1, 0.15, 0.2, 0.35, 0.5, 0.65, 0.8];
        for direction in [GridDirection::First, GridDirection::Second] {
            let along: &[f64] = if direction == GridDirection::First {
                &x1
            } else {
                &x2
            };
            let mut mesh = Mesh::default();
            let coarsening = Coarsening {
                direction,
                fine: vec![true, false, false, false],
                groups: vec![2, 2],
            };
            mesh.add_block_coarsened(9, 9, 0, |i, j| [1.0 + x1[i], x2[j]], along, &coarsening);
            // one fine line of 4 elements, three coarse lines of 2
            assert_eq!(mesh.elements.len(), 4 + 3 * 2, "{direction:?}");
            assert!(
                mesh.elements
                    .iter()
                    .all(|e| mesh.parent_jacobian(&e.nodes) > 0.0)
            );
            // the nodes at odd positions between the coarse nodes of three coarse lines
            // (7 positions across, 4 along each): 28 hanging
            assert_eq!(mesh.hanging.len(), 7 * 4, "{direction:?}");
            let coordinate = |n: usize| {
                let [r, z] = mesh.nodes[n];
                if direction == GridDirection::First {
                    r - 1.0
                } else {
                    z
                }
            };
            let f = |x: f64| 0.3 - 2.0 * x + 1.7 * x * x;
            for h in &mesh.hanging {
                let weights: f64 = h.masters.iter().map(|&(_, w)| w).sum();
                assert!((weights - 1.0).abs() < 1e-12);
                let v: f64 = h.masters.iter().map(|&(m, w)| w * f(coordinate(m))).sum();
                assert!((v - f(coordinate(h.node))).abs() < 1e-12, "{direction:?}");
                assert!(
                    h.masters
                        .iter()
                        .all(|&(m, _)| mesh.hanging.iter().all(|o| o.node != m))
                );
            }
        }
    }

    #[test]
    fn shell_elements_have_positive_jacobians() {
        let mut mesh = Mesh::default();
        let shell = add_shell(
            &mut mesh,
            &ShellGeometry {
                inner_radius_mm: 4.6,
                outer_radius_mm: 5.0,
                skirt_length_mm: 4.0,
            },
            &ShellDivisions {
                arc: 8,
                skirt: 3,
                thickness: 2,
            },
            0,
        );
        for e in &mesh.elements {
            assert!(mesh.parent_jacobian(&e.nodes) > 0.0);
        }
        assert_eq!(mesh.nodes[shell.inner_apex], [0.0, -4.6]);
        assert_eq!(mesh.nodes[shell.outer_apex], [0.0, -5.0]);
        assert_eq!(shell.clamped.len(), 7);
    }

    #[test]
    fn graded_arc_is_fine_near_the_apex_and_covers_the_quarter() {
        let grading = ArcGrading {
            refinement: 4,
            fine_angle_rad: 0.9,
            growth: 1.3,
        };
        let e = grading.edges(40);
        let quarter = std::f64::consts::FRAC_PI_2;
        assert!((e[e.len() - 1] - quarter).abs() < 1e-12);
        assert!(e.windows(2).all(|w| w[1] > w[0]));
        // fine elements up to the fine angle (at most quarter / 160 each, a whole number of
        // them), none much longer than the uniform ones
        let fine = quarter / 160.0;
        assert!(e[1] <= fine && e[1] > 0.95 * fine);
        assert!(
            e.windows(2)
                .all(|w| w[1] - w[0] <= 1.5 * quarter / 40.0 + 1e-12)
        );
        assert_eq!(ArcGrading::UNIFORM.edges(8).len(), 9);
    }
}
