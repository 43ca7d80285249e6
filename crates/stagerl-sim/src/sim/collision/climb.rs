//! A mesh part's support function by hill climbing (for GJK, the exact test of a mesh part):
//! the vertex farthest along a direction is found by walking the hull's edges from a start
//! vertex to a neighbour farther along, until none is. On a convex polyhedron a vertex no
//! neighbour beats is a farthest vertex (a linear function has no other local maximum on it),
//! so the answer is parry's linear scan's; from the last answer (the shapes move a little
//! between steps and GJK's directions a little between iterations) the walk is a few edges
//! instead of a pass over all vertices. Ties may give another vertex as far along.

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

    /// The index of a vertex farthest along `dir`, walking from vertex `start`.
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
            let (lo, hi) = (self.offsets[at as usize] as usize, self.offsets[at as usize + 1] as usize);
            let mut next = at;
            for &j in &self.neighbours[lo..hi] {
                let d = self.points[j as usize].dot(dir);
                if d > best {
                    best = d;
                    next = j;
                }
            }
            if next == at {
                return at;
            }
            at = next;
        }
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
    /// start, the walk ends at a vertex as far along as parry's linear scan finds.
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
            }
        }
    }
}
