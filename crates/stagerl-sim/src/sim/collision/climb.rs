//! A mesh part's support function by hill climbing (for GJK, the exact test of a mesh part):
//! the vertex farthest along a direction is found by walking the hull's edges from a start
//! vertex to a neighbour farther along, until none is. On a convex polyhedron a vertex no
//! neighbour beats is a farthest vertex (a linear function has no other local maximum on it),
//! so the answer is parry's linear scan's; from the last answer (the shapes move a little
//! between steps and GJK's directions a little between iterations) the walk is a few edges
//! instead of a pass over all vertices. Of vertices equally far (a face square to the
//! direction), the lowest index is returned, as parry's scan does: GJK then takes the same
//! steps as with parry's own support function, whatever the walk's start.

use std::sync::atomic::{AtomicU32, Ordering};

use parry3d::math::Vec3;
use parry3d::shape::{ConvexPolyhedron, SupportMap};

/// A hull's vertices and, for each, its neighbours along the hull's edges (compressed rows).
#[derive(Clone, Debug)]
pub(crate) struct Climber {
    points: Vec<Vec3>,
    offsets: Vec<u32>,
    neighbours: Vec<u32>,
    /// The farthest vertices along 26 directions (the axes, the face and the edge diagonals of
    /// a cube): a walk starts from the one of these, or the warm start, farthest along, so that
    /// a turn of the direction costs a few edges even on a finely tessellated round hull.
    anchors: Vec<u32>,
}

impl Climber {
    pub(crate) fn of(hull: &ConvexPolyhedron) -> Climber {
        let points = hull.points().to_vec();
        let n = points.len();
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); n];
        // Every edge parry's hull keeps (the diagonals of merged coplanar triangles too: extra
        // edges between hull vertices leave a vertex no neighbour beats a farthest one).
        for e in hull.edges() {
            let [a, b] = e.vertices;
            if (a as usize) < n && (b as usize) < n && a != b {
                lists[a as usize].push(b);
                lists[b as usize].push(a);
            }
        }
        let mut offsets = Vec::with_capacity(n + 1);
        let mut neighbours = Vec::new();
        offsets.push(0);
        for mut l in lists {
            l.sort_unstable();
            l.dedup();
            neighbours.extend(l);
            offsets.push(neighbours.len() as u32);
        }
        let mut anchors: Vec<u32> = Vec::new();
        for x in -1..=1 {
            for y in -1..=1 {
                for z in -1..=1 {
                    if (x, y, z) == (0, 0, 0) {
                        continue;
                    }
                    let d = Vec3::new(x as f32, y as f32, z as f32);
                    let best =
                        (0..points.len()).max_by(|&i, &j| points[i].dot(d).total_cmp(&points[j].dot(d)));
                    if let Some(i) = best.map(|i| i as u32).filter(|i| !anchors.contains(i)) {
                        anchors.push(i);
                    }
                }
            }
        }
        Climber { points, offsets, neighbours, anchors }
    }

    /// The index of the first (lowest-index) vertex farthest along `dir`, as parry's linear
    /// scan gives it, walking from vertex `start`: the answer does not depend on the start, so
    /// neither do GJK's steps nor its verdict (a resumed run checks as the uninterrupted one).
    #[inline]
    pub(crate) fn support(&self, dir: Vec3, start: u32) -> u32 {
        let mut at = if (start as usize) < self.points.len() { start } else { 0 };
        let mut best = self.points[at as usize].dot(dir);
        for &i in &self.anchors {
            let d = self.points[i as usize].dot(dir);
            if d > best {
                best = d;
                at = i;
            }
        }
        // Each move is to a vertex strictly farther along: the walk ends (at most once per vertex).
        loop {
            let (mut next, mut tied) = (at, false);
            for &j in self.neighbours_of(at) {
                let d = self.points[j as usize].dot(dir);
                if d > best {
                    best = d;
                    next = j;
                } else {
                    tied |= d == best;
                }
            }
            if next == at {
                // No neighbour is farther; one as far means a plateau to search.
                return if tied { self.lowest_on_plateau(at, best, dir) } else { at };
            }
            at = next;
        }
    }

    fn neighbours_of(&self, i: u32) -> &[u32] {
        let (lo, hi) = (self.offsets[i as usize] as usize, self.offsets[i as usize + 1] as usize);
        &self.neighbours[lo..hi]
    }

    /// The lowest index among the vertices as far along as `at` (`best`): they form a face, an
    /// edge or a vertex of the hull, connected by its edges. A plateau larger than the search's
    /// fixed room (no allocation) falls back to parry's linear scan.
    fn lowest_on_plateau(&self, at: u32, best: f32, dir: Vec3) -> u32 {
        const ROOM: usize = 64;
        let (mut seen, mut len, mut next) = ([0u32; ROOM], 1, 0);
        seen[0] = at;
        while next < len {
            let v = seen[next];
            next += 1;
            for &j in self.neighbours_of(v) {
                if self.points[j as usize].dot(dir) == best && !seen[..len].contains(&j) {
                    if len == ROOM {
                        return parry3d::utils::point_cloud_support_point_id(dir, &self.points) as u32;
                    }
                    seen[len] = j;
                    len += 1;
                }
            }
        }
        seen[..len].iter().copied().min().unwrap_or(at)
    }

    pub(crate) fn point(&self, i: u32) -> Vec3 {
        self.points[i as usize]
    }
}

/// A [`Climber`] as a support map for parry's GJK, starting each walk where the last ended
/// (`at`, the shape's warm start kept by the collider between tests; relaxed atomics: one
/// thread uses a collider at a time, and any start gives a farthest vertex).
pub(crate) struct Warm<'a> {
    pub(crate) climber: &'a Climber,
    pub(crate) at: &'a AtomicU32,
}

impl SupportMap for Warm<'_> {
    #[inline]
    fn local_support_point(&self, dir: Vec3) -> Vec3 {
        let i = self.climber.support(dir, self.at.load(Ordering::Relaxed));
        self.at.store(i, Ordering::Relaxed);
        self.climber.point(i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::base::rng::Rng;

    /// On random hulls (round, tessellated finely, and blobs) and random directions, from any
    /// start, the walk ends at the vertex parry's linear scan finds; on a box, whose faces tie
    /// along the axes, too.
    #[test]
    fn the_walk_finds_a_farthest_vertex_from_any_start() {
        let mut rng = Rng::new(9);
        for case in 0..30 {
            let pts: Vec<Vec3> = (0..20 + 40 * case)
                .map(|_| {
                    let v = Vec3::new(rng.normal() as f32, rng.normal() as f32, rng.normal() as f32);
                    // Every other case on a sphere: many vertices, all on the hull.
                    if case % 2 == 0 {
                        v.normalize() * 0.1
                    } else {
                        v * Vec3::new(0.3, 0.05, 0.05)
                    }
                })
                .collect();
            let hull = ConvexPolyhedron::from_convex_hull(&pts).unwrap();
            let c = Climber::of(&hull);
            for _ in 0..200 {
                let dir = Vec3::new(rng.normal() as f32, rng.normal() as f32, rng.normal() as f32);
                let start = rng.below(hull.points().len() as u64) as u32;
                let got = c.point(c.support(dir, start)).dot(dir);
                let want = hull.points().iter().map(|p| p.dot(dir)).fold(f32::NEG_INFINITY, f32::max);
                assert_eq!(got, want, "case {case}");
                // The very vertex parry's scan gives (the first of the farthest), from any start.
                let first = hull.points().iter().position(|p| p.dot(dir) == want).unwrap() as u32;
                assert_eq!(c.support(dir, start), first, "case {case}");
            }
        }
        let corners: Vec<Vec3> = (0..8)
            .map(|i| Vec3::new((i & 1) as f32 - 0.5, (i >> 1 & 1) as f32 - 0.5, (i >> 2 & 1) as f32 - 0.5))
            .collect();
        let hull = ConvexPolyhedron::from_convex_hull(&corners).unwrap();
        let c = Climber::of(&hull);
        for dir in [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z, Vec3::new(1.0, 1.0, 0.0)] {
            let want = hull.points().iter().map(|p| p.dot(dir)).fold(f32::NEG_INFINITY, f32::max);
            let first = hull.points().iter().position(|p| p.dot(dir) == want).unwrap() as u32;
            for start in 0..8 {
                assert_eq!(c.support(dir, start), first, "{dir:?} from {start}");
            }
        }
    }
}
