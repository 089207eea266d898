//! Issue 23: a scan's splats against the exact surface the scan was taken
//! of (`docs/notes/generation.md`, "Issue 23: the coarse case against the exact
//! surface"). Holds out the points `scan-check` holds out, grows splats from
//! the rest, and for each held-out line of sight compares the resolved
//! surface's `t` with the exact mesh's along the same ray: the error split
//! by cause (the splat centre's height over the mesh, its tilt, the rest),
//! by the angle of the line of sight, and as the share of the figure it
//! costs (the check's expected figure given these splats with the points'
//! range noise, `SIGMA`). The points' own heights and normals after the
//! projection are measured on a replica of the pipeline's first stages.
//!
//! `cargo run --release --example coarse_error -- CLOUD MESH X,Y,Z [SIGMA]`
//! (the scanner's position; `SIGMA` the range noise `sample` reported,
//! default 0.0159).

use glam::{DVec3, Vec3};
use splatray::accel::{CandidateHits, Ray, registry};
use splatray::embree::{Device, TriangleScene};
use splatray::freespace::sight_line;
use splatray::io::{read_mesh, read_points};
use splatray::pipeline::generate_uncoloured;
use splatray::resolve::{Resolved, ShadingMode, resolve_within};
use splatray::splat::knn::{Knn, build_tree};
use splatray::splat::{SplatParams, Viewpoints, denoise, normals, outliers};
use splatray::validate::holdout;
use std::path::Path;

struct Truth {
    scene: TriangleScene,
    pos: Vec<Vec3>,
    tris: Vec<[u32; 3]>,
}

impl Truth {
    fn hit(&self, o: Vec3, d: Vec3) -> Option<(f32, Vec3)> {
        let h = self
            .scene
            .intersect(&Ray { origin: o, dir: d }, 0.0, f32::INFINITY)?;
        let [a, b, c] = self.tris[h.triangle as usize].map(|k| self.pos[k as usize]);
        Some((h.t, (b - a).cross(c - a).normalize()))
    }
    /// Signed height of `p` above the mesh along `n` (searching both ways),
    /// with the true normal there.
    fn height(&self, p: Vec3, n: Vec3) -> Option<(f32, Vec3)> {
        let up = self.hit(p, n);
        let down = self.hit(p, -n);
        match (up, down) {
            (Some((tu, nu)), Some((td, nd))) => {
                if tu < td {
                    Some((-tu, nu))
                } else {
                    Some((td, nd))
                }
            }
            (Some((tu, nu)), None) => Some((-tu, nu)),
            (None, Some((td, nd))) => Some((td, nd)),
            _ => None,
        }
        .filter(|x| x.0.abs() < 0.2)
    }
}

fn erf(x: f64) -> f64 {
    // Abramowitz-Stegun 7.1.26
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let y = 1.0
        - (((((1.061_405_429 * t - 1.453_152_027) * t) + 1.421_413_741) * t - 0.284_496_736) * t
            + 0.254_829_592)
            * t
            * (-x * x).exp();
    if x < 0.0 { -y } else { y }
}

fn stats(name: &str, mut v: Vec<f32>) {
    if v.is_empty() {
        println!("{name}: none");
        return;
    }
    v.sort_by(f32::total_cmp);
    let med = v[v.len() / 2];
    let mut dev: Vec<f32> = v.iter().map(|x| (x - med).abs()).collect();
    dev.sort_by(f32::total_cmp);
    let mad = 1.4826 * dev[dev.len() / 2];
    let mean = v.iter().sum::<f32>() / v.len() as f32;
    let rms = (v.iter().map(|x| x * x).sum::<f32>() / v.len() as f32).sqrt();
    println!(
        "{name}: n {} median {med:.5} robust sd {mad:.5} mean {mean:.5} rms {rms:.5}",
        v.len()
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let cloud = read_points(Path::new(&args[1])).unwrap();
    let mesh = read_mesh(Path::new(&args[2])).unwrap();
    let v: Vec<f64> = args[3].split(',').map(|s| s.parse().unwrap()).collect();
    let sig: f64 = args.get(4).map_or(0.0159, |s| s.parse().unwrap());
    let vp = cloud.local_viewpoint(DVec3::new(v[0], v[1], v[2]));
    let shift = (mesh.origin - cloud.origin).as_vec3();
    let pos: Vec<Vec3> = mesh.positions.iter().map(|p| *p + shift).collect();
    let device = Device::new().unwrap();
    let truth = Truth {
        scene: TriangleScene::new(&device, &[(&pos[..], &mesh.triangles[..])]).unwrap(),
        pos: pos.clone(),
        tris: mesh.triangles.clone(),
    };
    let sp = SplatParams {
        viewpoint: Some(vp),
        ..SplatParams::default()
    };
    let split = holdout::split(&cloud, &sp, 0.1, 1).unwrap();
    let mut train = split.train;
    train.viewpoint = Some(vp);

    // --- the points: raw and denoised against the truth (replicated pipeline)
    {
        let flags = outliers::find(&train.positions, 12, Some(&Viewpoints::One(vp)));
        let pts: Vec<Vec3> = train
            .positions
            .iter()
            .zip(&flags)
            .filter(|(_, f)| !**f)
            .map(|(p, _)| *p)
            .collect();
        let tree = build_tree(&pts);
        let knn12 = Knn::build(&tree, &pts, 12);
        let sights = Viewpoints::One(vp);
        let est = normals::estimate_multiscale(&pts, &tree, &knn12, Some(&sights), None);
        let mut nrm = est.normals;
        // The graph a scan-line cloud is widened to (k = 48).
        let knn = Knn::build(&tree, &pts, 48);
        let fixed = vec![false; pts.len()];
        normals::orient(&pts, &knn, &mut nrm, &fixed, Some(&sights));
        let fits = denoise::fit_all(&pts, &nrm, &knn);
        let mut raw = Vec::new();
        let mut den = Vec::new();
        let mut ang = Vec::new();
        for i in 0..pts.len() {
            let Some(f) = fits[i] else { continue };
            let q = pts[i] + nrm[i] * f.offset;
            if let (Some((h0, nt)), Some((h1, _))) =
                (truth.height(pts[i], nrm[i]), truth.height(q, nrm[i]))
            {
                raw.push(h0);
                den.push(h1);
                ang.push(nrm[i].dot(nt).clamp(-1.0, 1.0).acos().to_degrees());
            }
        }
        stats("raw point height vs truth", raw);
        stats("denoised point height vs truth", den);
        stats("point normal error deg", ang);
    }

    let splats = generate_uncoloured(&train, &sp, None).unwrap().splats;
    let backend = registry::renderers()[0].build_splats(&splats).unwrap();
    let window = 3.0 * splatray::splat::standoff::standoff(&splats);
    let mut hits = CandidateHits::new(window);
    let (mut e_res, mut e_pt, mut e_mean) = (Vec::new(), Vec::new(), Vec::new());
    let (mut hc, mut tilt, mut curv, mut hh) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut nerr = Vec::new();
    let (mut cons_pt, mut cons_truth, mut n) = (0usize, 0usize, 0usize);
    let mut by_cos: Vec<(f32, f32)> = Vec::new();
    let mut cons_phong = 0usize;
    let mut alt = [0f64; 4];
    let (mut exp_sum, mut ceil_sum) = (0f64, 0f64);
    let mut loss: Vec<(f64, f32, f64)> = Vec::new();
    for &p in &split.test {
        let Some((ray, d)) = sight_line(vp, p) else {
            continue;
        };
        let Some((tt, nt)) = truth.hit(ray.origin, ray.dir) else {
            continue;
        };
        if (d - tt).abs() > 0.1 {
            continue; // the point is on another surface than the first hit
        }
        hits.clear();
        backend.intersect(&ray, 0.0, f32::INFINITY, &mut hits);
        let Some(h) =
            resolve_within(&hits, &ray, &splats, ShadingMode::Flat, window).and_then(Resolved::hit)
        else {
            continue;
        };
        n += 1;
        let tol = 0.01 * d;
        {
            let mut hp = CandidateHits::new(window);
            let mut from = 0.0f32;
            for _ in 0..8 {
                hp.clear();
                backend.intersect(&ray, from, f32::INFINITY, &mut hp);
                match resolve_within(&hp, &ray, &splats, ShadingMode::Phong, window) {
                    Some(Resolved::Hit(x)) => {
                        cons_phong += usize::from((x.t - d).abs() <= tol);
                        break;
                    }
                    Some(Resolved::Beyond(t)) => from = t,
                    None => break,
                }
            }
        }
        cons_pt += usize::from((h.t - d).abs() <= tol);
        cons_truth += usize::from((h.t - tt).abs() <= tol);
        e_res.push(h.t - tt);
        e_pt.push(d - tt);
        let c = hits.as_slice();
        let m = c.iter().map(|c| c.t).sum::<f32>() / c.len() as f32;
        e_mean.push(m - tt);
        let cosr = ray.dir.dot(nt).abs();
        by_cos.push((cosr, h.t - tt));
        {
            let e = f64::from(h.t - tt);
            let t = f64::from(tol);
            let pr =
                0.5 * (erf((t - e) / (sig * 2f64.sqrt())) - erf((-t - e) / (sig * 2f64.sqrt())));
            let pr0 = 0.5 * (erf(t / (sig * 2f64.sqrt())) - erf(-t / (sig * 2f64.sqrt())));
            exp_sum += pr;
            let pe = |e: f64| {
                0.5 * (erf((t - e) / (sig * 2f64.sqrt())) - erf((-t - e) / (sig * 2f64.sqrt())))
            };
            let cs = hits.as_slice();
            let mut ts: Vec<f32> = cs.iter().map(|c| c.t).collect();
            ts.sort_by(f32::total_cmp);
            let med = ts[ts.len() / 2];
            let (mut ws, mut wt) = (0f32, 0f32);
            for c in cs {
                let w = (1.0 - c.radial()).max(0.0);
                ws += w;
                wt += w * c.t;
            }
            let wmean = if ws > 0.0 { wt / ws } else { h.t };
            let best_cos = cs
                .iter()
                .max_by(|x, y| {
                    ray.dir
                        .dot(splats[x.id as usize].normal)
                        .abs()
                        .total_cmp(&ray.dir.dot(splats[y.id as usize].normal).abs())
                })
                .unwrap()
                .t;
            for (k, tv) in [hits.nearest().unwrap().t, med, wmean, best_cos]
                .iter()
                .enumerate()
            {
                alt[k] += pe(f64::from(tv - tt));
            }
            ceil_sum += pr0;
            loss.push((pr0 - pr, cosr, e));
        }
        // Decompose the winner's plane height at the hit.
        let s = &splats[h.id as usize];
        let x = ray.origin + ray.dir * h.t;
        // height of the hit above truth along the true normal (approx.)
        let hx = -(h.t - tt) * cosr;
        if let Some((hcen, ntc)) = truth.height(s.center, s.normal) {
            let ntc = if ntc.dot(s.normal) < 0.0 { -ntc } else { ntc };
            let tl = (x - s.center).dot(ntc);
            hc.push(hcen);
            tilt.push(tl);
            curv.push(hx - hcen - tl);
            hh.push(hx);
            nerr.push(s.normal.dot(ntc).clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    println!(
        "rays {n}: consistent vs point {:.2} %, vs truth {:.2} %",
        100.0 * cons_pt as f64 / n as f64,
        100.0 * cons_truth as f64 / n as f64
    );
    println!(
        "alt expected: nearest {:.2} median {:.2} wmean {:.2} best-cos {:.2}",
        100.0 * alt[0] / n as f64,
        100.0 * alt[1] / n as f64,
        100.0 * alt[2] / n as f64,
        100.0 * alt[3] / n as f64
    );
    println!(
        "phong-resolved consistent vs point {:.2} %",
        100.0 * cons_phong as f64 / n as f64
    );
    println!(
        "expected consistent given these splats {:.2} %, ceiling {:.2} %",
        100.0 * exp_sum / n as f64,
        100.0 * ceil_sum / n as f64
    );
    for (lo, hi) in [(0.0, 0.01), (0.01, 0.02), (0.02, 0.036), (0.036, 1.0)] {
        let l: Vec<&(f64, f32, f64)> = loss
            .iter()
            .filter(|x| x.2.abs() >= lo && x.2.abs() < hi)
            .collect();
        println!(
            "  |e| {lo}-{hi}: {} rays, loss {:.2} % points",
            l.len(),
            100.0 * l.iter().map(|x| x.0).sum::<f64>() / n as f64
        );
    }
    for (lo, hi) in [(0.0, 0.3), (0.3, 0.6), (0.6, 0.85), (0.85, 1.01)] {
        let l: Vec<&(f64, f32, f64)> = loss.iter().filter(|x| x.1 >= lo && x.1 < hi).collect();
        println!(
            "  cos {lo}-{hi}: {} rays, loss {:.2} % points",
            l.len(),
            100.0 * l.iter().map(|x| x.0).sum::<f64>() / n as f64
        );
    }
    stats("point d - t_true (noise)", e_pt);
    stats("resolved t - t_true", e_res.clone());
    stats("window mean t - t_true", e_mean);
    stats("hit height above truth (normal)", hh);
    stats("  centre height", hc);
    stats("  tilt term (x-c).n_true", tilt);
    stats("  rest (curvature)", curv);
    stats("winner normal error deg", nerr);
    for (lo, hi) in [(0.0, 0.3), (0.3, 0.6), (0.6, 0.85), (0.85, 1.01)] {
        stats(
            &format!("  resolved err, cos {lo}-{hi}"),
            by_cos
                .iter()
                .filter(|c| c.0 >= lo && c.0 < hi)
                .map(|c| c.1)
                .collect(),
        );
    }
}
