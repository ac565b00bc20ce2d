//! Procedural geometry: the generated scenes that tests, benches and tools share.
//!
//! All generators are deterministic functions of their arguments (seeded where random).

use crate::math::Vec3;
use crate::rng::Rng;

/// An indexed triangle mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Triangles as vertex index triples.
    pub indices: Vec<[u32; 3]>,
}

impl Mesh {
    /// Appends `other`, offsetting its indices.
    pub fn append(&mut self, other: &Mesh) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.indices.extend(other.indices.iter().map(|t| t.map(|i| i + base)));
    }

    /// Applies `f` to every vertex.
    pub fn map_positions(mut self, f: impl Fn(Vec3) -> Vec3) -> Self {
        for p in &mut self.positions {
            *p = f(*p);
        }
        self
    }
}

/// `n` independent random triangles with corners in the cube `[-1, 1]³`, each with edges of
/// about `size` (a "triangle soup": no shared vertices).
pub fn random_soup(n: usize, size: f32, seed: u64) -> Mesh {
    let mut rng = Rng::new(seed, 0x50_4f_55_50);
    let r3 = |rng: &mut Rng| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
    let mut m = Mesh::default();
    for i in 0..n {
        let c = r3(&mut rng);
        for _ in 0..3 {
            let d = r3(&mut rng);
            m.positions.push(c + d * size);
        }
        let b = 3 * i as u32;
        m.indices.push([b, b + 1, b + 2]);
    }
    m
}

/// A `nx` × `ny` grid of quads (two triangles each, sharing edges) over `[-1,1]²` in the
/// `z = 0` plane.
pub fn grid(nx: usize, ny: usize) -> Mesh {
    let mut m = Mesh::default();
    for j in 0..=ny {
        for i in 0..=nx {
            m.positions.push(Vec3::new(2.0 * i as f32 / nx as f32 - 1.0, 2.0 * j as f32 / ny as f32 - 1.0, 0.0));
        }
    }
    let row = nx as u32 + 1;
    for j in 0..ny as u32 {
        for i in 0..nx as u32 {
            let a = j * row + i;
            m.indices.push([a, a + 1, a + row + 1]);
            m.indices.push([a, a + row + 1, a + row]);
        }
    }
    m
}

/// A closed UV sphere of radius 1 at the origin with `rings` latitude bands and `segments`
/// longitude segments; every edge is shared by exactly two triangles.
pub fn uv_sphere(rings: usize, segments: usize) -> Mesh {
    let (rings, segments) = (rings.max(2), segments.max(3));
    let mut m = Mesh::default();
    m.positions.push(Vec3::Z);
    for r in 1..rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            m.positions.push(Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()));
        }
    }
    m.positions.push(-Vec3::Z);
    let seg = segments as u32;
    let ring = |r: u32, s: u32| 1 + (r - 1) * seg + s % seg;
    for s in 0..seg {
        m.indices.push([0, ring(1, s), ring(1, s + 1)]);
    }
    for r in 1..rings as u32 - 1 {
        for s in 0..seg {
            let (a, b, c, d) = (ring(r, s), ring(r, s + 1), ring(r + 1, s), ring(r + 1, s + 1));
            m.indices.push([a, c, d]);
            m.indices.push([a, d, b]);
        }
    }
    let south = m.positions.len() as u32 - 1;
    for s in 0..seg {
        m.indices.push([south, ring(rings as u32 - 1, s + 1), ring(rings as u32 - 1, s)]);
    }
    m
}

/// A torus knot `(p, q)` tube of radius `tube`, tessellated with `n_len` × `n_around`
/// quads and displaced by a deterministic ripple of relative `bump`: a closed mesh of
/// `2 n_len n_around` triangles, for large-scale tests (scale it to millions).
pub fn torus_knot(n_len: usize, n_around: usize, p: f32, q: f32, tube: f32, bump: f32) -> Mesh {
    let curve = |t: f32| {
        let r = 2.0 + (q * t).cos();
        Vec3::new(r * (p * t).cos(), r * (p * t).sin(), -(q * t).sin())
    };
    let mut m = Mesh::default();
    for i in 0..n_len {
        let t = std::f32::consts::TAU * i as f32 / n_len as f32;
        let c = curve(t);
        // Frenet frame: continuous and periodic, since a torus knot's curvature never vanishes.
        let h = 1e-2;
        let (prev, next) = (curve(t - h), curve(t + h));
        let tangent = (next - prev).normalize();
        let bend = next + prev - 2.0 * c;
        let u = (bend - tangent * bend.dot(tangent)).normalize();
        let v = tangent.cross(u);
        for j in 0..n_around {
            let a = std::f32::consts::TAU * j as f32 / n_around as f32;
            let ripple = 1.0 + bump * ((7.0 * a).sin() * (31.0 * t).sin());
            m.positions.push(c + (u * a.cos() + v * a.sin()) * tube * ripple);
        }
    }
    let (nl, na) = (n_len as u32, n_around as u32);
    for i in 0..nl {
        for j in 0..na {
            let idx = |i: u32, j: u32| (i % nl) * na + j % na;
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            m.indices.push([a, b, c]);
            m.indices.push([a, c, d]);
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn edge_counts(m: &Mesh) -> HashMap<(u32, u32), usize> {
        let mut e = HashMap::new();
        for t in &m.indices {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *e.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        e
    }

    #[test]
    fn closed_meshes_share_every_edge_twice() {
        for m in [uv_sphere(8, 12), torus_knot(40, 8, 2.0, 3.0, 0.4, 0.1)] {
            assert!(edge_counts(&m).values().all(|&c| c == 2));
        }
        assert_eq!(uv_sphere(8, 12).indices.len(), 2 * 12 * (8 - 1));
    }

    #[test]
    fn soup_and_grid_sizes() {
        assert_eq!(random_soup(10, 0.1, 1).indices.len(), 10);
        assert_eq!(random_soup(10, 0.1, 1), random_soup(10, 0.1, 1));
        let g = grid(4, 3);
        assert_eq!((g.positions.len(), g.indices.len()), (20, 24));
    }
}
