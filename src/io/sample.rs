//! Area-uniform point sampling of a triangle mesh.

use super::{Mesh, PointCloud};
use crate::rng::SplitMix64;
use glam::Vec3;
use rayon::prelude::*;

/// Points generated per independently seeded chunk, so the result does not
/// depend on the thread count.
const CHUNK: usize = 1 << 14;

/// Area-uniform sampling of one mesh, chunk by chunk: chunk `c` holds
/// points `c * CHUNK ..` and is drawn from its own seeded generator, so the
/// points do not depend on the thread count nor on how many chunks are made
/// at once.
pub struct MeshSampler {
    tris: Vec<[Vec3; 3]>,
    cdf: Vec<f64>,
    total: f64,
    sigma: f64,
    seed: u64,
    n: usize,
    origin: glam::DVec3,
}

impl MeshSampler {
    /// A sampler of `n` points on `mesh` (see [`sample_mesh`]).
    #[must_use]
    pub fn new(mesh: &Mesh, n: usize, noise_sigma: f32, seed: u64) -> MeshSampler {
        let nv = mesh.positions.len();
        let mut tris: Vec<[Vec3; 3]> = Vec::with_capacity(mesh.triangles.len());
        let mut cdf: Vec<f64> = Vec::with_capacity(mesh.triangles.len());
        let mut total = 0f64;
        for t in &mesh.triangles {
            if t.iter().any(|&i| i as usize >= nv) {
                continue;
            }
            let p = t.map(|i| mesh.positions[i as usize]);
            let area = 0.5 * f64::from((p[1] - p[0]).cross(p[2] - p[0]).length());
            if area.is_finite() && area > 0.0 {
                total += area;
                tris.push(p);
                cdf.push(total);
            }
        }
        MeshSampler {
            n: if tris.is_empty() { 0 } else { n },
            tris,
            cdf,
            total,
            sigma: f64::from(noise_sigma.max(0.0)),
            seed,
            origin: mesh.origin,
        }
    }

    /// Points this sampler makes: `n`, or 0 when the mesh has no usable
    /// triangle.
    #[must_use]
    pub fn len(&self) -> usize {
        self.n
    }

    /// True when it makes no point.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// How many chunks hold the points.
    #[must_use]
    pub fn chunks(&self) -> usize {
        self.n.div_ceil(CHUNK)
    }

    /// Chunk `c`: its points and their triangles' unit normals.
    #[must_use]
    pub fn chunk(&self, c: usize) -> (Vec<Vec3>, Vec<Vec3>) {
        let mut rng = SplitMix64::new(self.seed ^ (c as u64).wrapping_mul(0xD1B5_4A32_D192_ED03));
        let count = CHUNK.min(self.n - c * CHUNK);
        let mut pos = Vec::with_capacity(count);
        let mut nor = Vec::with_capacity(count);
        let sigma = self.sigma;
        for _ in 0..count {
            let target = rng.next_f64() * self.total;
            let ti = self
                .cdf
                .partition_point(|&a| a <= target)
                .min(self.tris.len() - 1);
            let [a, b, cc] = self.tris[ti];
            let (r1, r2) = (rng.next_f64().sqrt(), rng.next_f64());
            let (wa, wb, wc) = (1.0 - r1, r1 * (1.0 - r2), r1 * r2);
            let p = a * wa as f32 + b * wb as f32 + cc * wc as f32;
            let noise = if sigma > 0.0 {
                Vec3::new(
                    (rng.next_gaussian() * sigma) as f32,
                    (rng.next_gaussian() * sigma) as f32,
                    (rng.next_gaussian() * sigma) as f32,
                )
            } else {
                Vec3::ZERO
            };
            pos.push(p + noise);
            nor.push((b - a).cross(cc - a).normalize_or_zero());
        }
        (pos, nor)
    }
}

/// `n` points sampled uniformly by area from `mesh`, each with its triangle's
/// unit normal (right-hand rule on the vertex order), optionally displaced
/// by isotropic Gaussian noise of standard deviation `noise_sigma` (in the
/// mesh's units). The same `seed` gives the same points on any machine and
/// thread count. Degenerate (zero-area or non-finite) triangles are never
/// sampled; a mesh without any usable triangle gives an empty cloud.
#[must_use]
pub fn sample_mesh(mesh: &Mesh, n: usize, noise_sigma: f32, seed: u64) -> PointCloud {
    let sampler = MeshSampler::new(mesh, n, noise_sigma, seed);
    let parts: Vec<(Vec<Vec3>, Vec<Vec3>)> = (0..sampler.chunks())
        .into_par_iter()
        .map(|c| sampler.chunk(c))
        .collect();
    let mut positions = Vec::with_capacity(sampler.len());
    let mut normals = Vec::with_capacity(sampler.len());
    for (p, q) in parts {
        positions.extend(p);
        normals.extend(q);
    }
    PointCloud {
        positions,
        normals: Some(normals),
        colors: None,
        origin: mesh.origin,
        ..PointCloud::default()
    }
}

/// Chunks made at once by [`write_sample_ply`]: 64 × 16,384 points, about
/// 25 MB of records (50 MB for a far mesh's f64 positions).
const CHUNKS_AT_ONCE: usize = 64;

/// Writes the points of `sampler` (as [`sample_mesh`] makes them) as a
/// binary PLY a batch of chunks at a time, so memory stays bounded whatever
/// their number: the bytes are those [`super::write_points`] writes for the
/// same cloud. `progress` hears the fraction written.
///
/// # Errors
/// An [`IoError`](super::IoError) when the file cannot be written (nothing
/// is left at `path`).
pub fn write_sample_ply(
    path: &std::path::Path,
    sampler: &MeshSampler,
    progress: Option<crate::progress::Progress<'_>>,
) -> Result<(), super::IoError> {
    use std::io::Write;
    let wide = sampler.origin != glam::DVec3::ZERO;
    let header = super::ply_points_header(sampler.len(), wide, true, false);
    super::write_atomic(path, |tmp| -> std::io::Result<()> {
        let mut out = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(tmp)?);
        out.write_all(header.as_bytes())?;
        let chunks = sampler.chunks();
        let mut buf = Vec::new();
        for first in (0..chunks).step_by(CHUNKS_AT_ONCE) {
            let last = (first + CHUNKS_AT_ONCE).min(chunks);
            let parts: Vec<(Vec<Vec3>, Vec<Vec3>)> = (first..last)
                .into_par_iter()
                .map(|c| sampler.chunk(c))
                .collect();
            for (positions, normals) in parts {
                let part = PointCloud {
                    positions,
                    normals: Some(normals),
                    origin: sampler.origin,
                    ..PointCloud::default()
                };
                buf.clear();
                super::encode_records(&mut buf, &part, wide, part.normals.as_ref(), None);
                out.write_all(&buf)?;
            }
            crate::progress::notify(progress, "sampling", last as f64 / chunks as f64);
        }
        out.flush()
    })
}
