//! Area-uniform point sampling of a triangle mesh.

use super::{Mesh, PointCloud};
use crate::rng::SplitMix64;
use glam::Vec3;
use rayon::prelude::*;

/// Points generated per independently seeded chunk, so the result does not
/// depend on the thread count.
const CHUNK: usize = 1 << 14;

/// `n` points sampled uniformly by area from `mesh`, each with its triangle's
/// unit normal (right-hand rule on the vertex order), optionally displaced
/// by isotropic Gaussian noise of standard deviation `noise_sigma` (in the
/// mesh's units). The same `seed` gives the same points on any machine and
/// thread count. Degenerate (zero-area or non-finite) triangles are never
/// sampled; a mesh without any usable triangle gives an empty cloud.
#[must_use]
pub fn sample_mesh(mesh: &Mesh, n: usize, noise_sigma: f32, seed: u64) -> PointCloud {
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
    if tris.is_empty() || n == 0 {
        return PointCloud {
            normals: Some(Vec::new()),
            ..PointCloud::default()
        };
    }
    let sigma = f64::from(noise_sigma.max(0.0));
    let chunks = n.div_ceil(CHUNK);
    let parts: Vec<(Vec<Vec3>, Vec<Vec3>)> = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut rng = SplitMix64::new(seed ^ (c as u64).wrapping_mul(0xD1B5_4A32_D192_ED03));
            let count = CHUNK.min(n - c * CHUNK);
            let mut pos = Vec::with_capacity(count);
            let mut nor = Vec::with_capacity(count);
            for _ in 0..count {
                let target = rng.next_f64() * total;
                let ti = cdf.partition_point(|&a| a <= target).min(tris.len() - 1);
                let [a, b, cc] = tris[ti];
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
        })
        .collect();
    let mut positions = Vec::with_capacity(n);
    let mut normals = Vec::with_capacity(n);
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
