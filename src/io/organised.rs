//! An organised cloud (a depth camera's or stereo rig's grid, a point per
//! pixel), the pinhole that explains its grid, and the rays of its empty
//! cells.
//!
//! In the sensor's frame (`p_s = R⁻¹ (p - t)`, with the pose `t`, `R` of
//! the file's `VIEWPOINT`), the point of pixel `(u, v)` (column and row,
//! pixel centres at integers) satisfies `u = fx·x/z + cx` and
//! `v = fy·y/z + cy`: two straight-line fits, by least squares over every
//! measured pixel, with their RMS residual. The signs tell the frame: the
//! optical frame of PCL, OpenCV and ROS (`x` right, `y` down, `z` forward:
//! `z > 0`, `fx, fy > 0`) or the OpenGL one (`y` up, looking along `-z`:
//! `z < 0`, `fx < 0`, `fy > 0`). The same pinhole gives the ray of a pixel
//! the capture left empty: free space to infinity when its neighbours are
//! empty too ([`grid_misses`]).

use glam::{DVec3, Vec3};

/// An organised cloud (`HEIGHT` > 1): the grid of a depth camera or stereo
/// rig, a point per pixel, row by row, NaN where nothing was measured.
#[derive(Clone, Debug, PartialEq)]
pub struct Organised {
    /// Pixels per row, and rows.
    pub width: usize,
    /// See `width`.
    pub height: usize,
    /// The sensor's position (`VIEWPOINT`), in the file's coordinates.
    pub position: DVec3,
    /// The sensor's orientation (`VIEWPOINT`'s quaternion, normalised).
    pub orientation: glam::DQuat,
    /// Every measured pixel: its index (`row · width + column`) and its
    /// point, in the file's coordinates.
    pub pixels: Vec<(u32, DVec3)>,
    /// Linear colours of `pixels`, when the file has them.
    pub colors: Option<Vec<Vec3>>,
}

/// The pinhole fitted to an organised grid, in the sensor's frame (the
/// signs as fitted: see the module's note).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pinhole {
    /// Focal length along the rows, pixels (negative in the `-z` frame).
    pub fx: f64,
    /// Focal length along the columns, pixels.
    pub fy: f64,
    /// Principal point, pixels from the left edge.
    pub cx: f64,
    /// Principal point, pixels from the top edge.
    pub cy: f64,
    /// Whether the sensor looks along `+z` of its frame (else `-z`).
    pub forward_z: bool,
    /// RMS distance, pixels, of the measured points from where the pinhole
    /// projects them.
    pub residual: f64,
}

impl Pinhole {
    /// Unit direction, in the sensor's frame, of the ray through pixel
    /// `(u, v)`: the inverse of the projection, `(x/z, y/z) =
    /// ((u - cx)/fx, (v - cy)/fy)`, on the side the sensor looks to.
    #[must_use]
    pub fn ray(&self, u: f64, v: f64) -> DVec3 {
        let s = if self.forward_z { 1.0 } else { -1.0 };
        (s * DVec3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0)).normalize()
    }
}

/// Least-squares line `y = a x + b` through `(x, y)` pairs, with the RMS
/// residual; `None` when the `x` do not spread.
fn line(pairs: impl Iterator<Item = (f64, f64)> + Clone) -> Option<(f64, f64, f64)> {
    let (mut n, mut sx, mut sy) = (0f64, 0f64, 0f64);
    for (x, y) in pairs.clone() {
        n += 1.0;
        sx += x;
        sy += y;
    }
    if n < 2.0 {
        return None;
    }
    let (mx, my) = (sx / n, sy / n);
    let (mut sxx, mut sxy) = (0f64, 0f64);
    for (x, y) in pairs.clone() {
        sxx += (x - mx) * (x - mx);
        sxy += (x - mx) * (y - my);
    }
    if sxx.is_nan() || sxx <= 1e-18 * n {
        return None;
    }
    let a = sxy / sxx;
    let b = my - a * mx;
    let ss: f64 = pairs.map(|(x, y)| (y - a * x - b).powi(2)).sum();
    Some((a, b, (ss / n).sqrt()))
}

impl Organised {
    /// The pinhole of the grid, fitted by least squares.
    ///
    /// # Errors
    /// One line: too few measured pixels off the sensor's plane, or pixels
    /// that do not spread across the grid (no pinhole explains them).
    pub fn pinhole(&self) -> Result<Pinhole, String> {
        let inv = self.orientation.inverse();
        let w = self.width.max(1) as u64;
        // Points in the sensor's frame, with their pixel.
        let pts: Vec<(f64, f64, DVec3)> = self
            .pixels
            .iter()
            .map(|&(i, p)| {
                let i = u64::from(i);
                ((i % w) as f64, (i / w) as f64, inv * (p - self.position))
            })
            .filter(|(_, _, p)| p.z.abs() > 1e-9 * p.length())
            .collect();
        if pts.len() < 16 {
            return Err(format!(
                "an organised cloud needs at least 16 measured pixels off the sensor's plane to \
                 fit its camera, this one has {}",
                pts.len()
            ));
        }
        let forward_z = pts.iter().filter(|(_, _, p)| p.z > 0.0).count() * 2 >= pts.len();
        let s = if forward_z { 1.0 } else { -1.0 };
        // Points behind the sensor are not on its grid.
        let front: Vec<&(f64, f64, DVec3)> = pts.iter().filter(|(_, _, p)| p.z * s > 0.0).collect();
        let fit_u = line(front.iter().map(|(u, _, p)| (p.x / p.z, *u)));
        let fit_v = line(front.iter().map(|(_, v, p)| (p.y / p.z, *v)));
        let (Some((fx, cx, ru)), Some((fy, cy, rv))) = (fit_u, fit_v) else {
            return Err(
                "the organised cloud's points do not spread across its grid: no camera fits".into(),
            );
        };
        Ok(Pinhole {
            fx,
            fy,
            cx,
            cy,
            forward_z,
            residual: (0.5 * (ru * ru + rv * rv)).sqrt(),
        })
    }

    /// Unit directions, in the file's frame, of the rays through the grid's
    /// empty cells that met nothing ([`Organised::miss_cells`]), as
    /// `pinhole` casts them from the sensor.
    #[must_use]
    pub fn misses(&self, pinhole: &Pinhole) -> Vec<Vec3> {
        self.miss_cells()
            .into_iter()
            .map(|k| self.cell_ray(pinhole, k))
            .collect()
    }

    /// The grid's empty cells with at least two empty neighbours
    /// ([`grid_misses`]) whose empty region reaches the grid's edge, as
    /// indices `row · width + column`.
    ///
    /// An empty region the measured pixels enclose is left out: a stereo
    /// rig leaves NaN where it found no match (a surface without texture,
    /// a reflection), in the middle of a surface it did see, and a ray
    /// through such a pixel proves no free space; trimming along it would
    /// cut a hole in that surface. Free space past everything (a depth
    /// camera's rays beyond its range, the background round an object)
    /// runs out to the edge of the image. The cost: a true hole through an
    /// object seen against nothing (a mug's handle) trims nothing.
    #[must_use]
    pub fn miss_cells(&self) -> Vec<usize> {
        let mut filled = vec![None; self.width * self.height];
        for &(i, _) in &self.pixels {
            if let Some(f) = filled.get_mut(i as usize) {
                *f = Some(());
            }
        }
        let open = open_to_edge(&filled, self.width, self.height);
        grid_misses(&filled, self.width, self.height)
            .into_iter()
            .filter(|&k| open[k])
            .collect()
    }

    /// Unit direction, in the file's frame, of `pinhole`'s ray through cell
    /// `k` (`row · width + column`).
    #[must_use]
    pub fn cell_ray(&self, pinhole: &Pinhole, k: usize) -> Vec3 {
        let w = self.width.max(1);
        let (u, v) = ((k % w) as f64, (k / w) as f64);
        (self.orientation * pinhole.ray(u, v)).as_vec3()
    }
}

/// For each cell of a grid (`cols` × `rows`, row by row): is it empty and
/// joined to the grid's edge through empty cells (four-neighbour steps)?
fn open_to_edge<T>(grid: &[Option<T>], cols: usize, rows: usize) -> Vec<bool> {
    let n = grid.len().min(cols * rows);
    let mut open = vec![false; grid.len()];
    let mut stack: Vec<usize> = (0..n)
        .filter(|&k| {
            let (c, r) = (k % cols, k / cols);
            grid[k].is_none() && (c == 0 || r == 0 || c + 1 == cols || r + 1 == rows)
        })
        .collect();
    for &k in &stack {
        open[k] = true;
    }
    while let Some(k) = stack.pop() {
        let (c, r) = (k % cols, k / cols);
        let next = [
            (c > 0).then(|| k - 1),
            (c + 1 < cols).then(|| k + 1),
            (r > 0).then(|| k - cols),
            (r + 1 < rows).then(|| k + cols),
        ];
        for j in next.into_iter().flatten() {
            if j < n && !open[j] && grid[j].is_none() {
                open[j] = true;
                stack.push(j);
            }
        }
    }
    open
}

/// The cells of a scan's grid (`cols` × `rows`, row by row) that hold no
/// point and have at least two empty cells among their four neighbours:
/// rays that met nothing, as an organised capture shows them. A lone empty
/// cell is more likely a return that went missing (a dropout) than a ray
/// past everything, and is left out, as is one with a single empty
/// neighbour (two dropouts side by side).
#[must_use]
pub fn grid_misses<T>(grid: &[Option<T>], cols: usize, rows: usize) -> Vec<usize> {
    let empty = |c: usize, r: usize| grid.get(r * cols + c).is_some_and(Option::is_none);
    (0..grid.len().min(cols * rows))
        .filter(|&k| {
            let (c, r) = (k % cols, k / cols);
            if !empty(c, r) {
                return false;
            }
            let near = [
                c > 0 && empty(c - 1, r),
                c + 1 < cols && empty(c + 1, r),
                r > 0 && empty(c, r - 1),
                r + 1 < rows && empty(c, r + 1),
            ];
            near.iter().filter(|&&e| e).count() >= 2
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::{Organised, grid_misses};
    use glam::{DQuat, DVec3};

    /// A 5 × 4 grid: the right two columns empty (past an edge), one lone
    /// empty cell and a pair side by side inside (dropped returns).
    #[test]
    fn misses_are_empty_cells_beside_empty_cells() {
        let o = Some(());
        let grid = [
            o, o, o, None, None, //
            o, None, o, None, None, //
            o, o, o, None, None, //
            None, None, o, None, None,
        ];
        let m = grid_misses(&grid, 5, 4);
        assert_eq!(m, vec![3, 4, 8, 9, 13, 14, 18, 19]);
    }

    /// A 6 × 5 grid: a 2 × 2 empty block inside (a stereo rig's "no
    /// match", enclosed by measured cells) and an empty column at the right
    /// edge. Both give misses to `grid_misses`; only the column reaches
    /// the edge, so only its misses are a capture's.
    #[test]
    fn enclosed_empty_cells_are_no_misses() {
        let o = Some(());
        #[rustfmt::skip]
        let grid = [
            o, o, o, o, o, None,
            o, None, None, o, o, None,
            o, None, None, o, o, None,
            o, o, o, o, o, None,
            o, o, o, o, o, None,
        ];
        // (The column's end cells have one empty neighbour: dropouts.)
        assert_eq!(grid_misses(&grid, 6, 5), vec![7, 8, 11, 13, 14, 17, 23]);
        let open = super::open_to_edge(&grid, 6, 5);
        let open: Vec<usize> = (0..30).filter(|&k| open[k]).collect();
        assert_eq!(open, vec![5, 11, 17, 23, 29]);
        let capture = Organised {
            width: 6,
            height: 5,
            position: DVec3::ZERO,
            orientation: DQuat::IDENTITY,
            pixels: (0..30u32)
                .filter(|&k| grid[k as usize].is_some())
                .map(|k| (k, DVec3::new(f64::from(k % 6), f64::from(k / 6), 1.0)))
                .collect(),
            colors: None,
        };
        assert_eq!(capture.miss_cells(), vec![11, 17, 23]);
    }

    /// A 40 × 30 capture of a slanted plane by a known pinhole in the
    /// `-z` frame, turned and moved, its right third empty: the fit gives
    /// the pinhole back and an empty pixel's ray is the pinhole's ray
    /// through it, in the file's frame.
    #[test]
    fn an_empty_pixel_s_ray_is_the_fitted_pinhole_s() {
        let (fx, fy, cx, cy) = (-52.5, 51.0, 18.3, 14.2);
        let q = DQuat::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 0.7);
        let t = DVec3::new(100.0, -3.0, 7.5);
        // The pinhole's ray through (u, v) in the sensor's frame (-z).
        let ray = |u: f64, v: f64| -DVec3::new((u - cx) / fx, (v - cy) / fy, 1.0);
        let (w, h) = (40usize, 30usize);
        let mut pixels = Vec::new();
        for k in 0..w * h {
            let (u, v) = ((k % w) as f64, (k / w) as f64);
            if u < 27.0 {
                let d = ray(u, v);
                // The plane z = -2 - 0.02 u in the sensor's frame.
                let depth = 2.0 + 0.02 * u;
                pixels.push((k as u32, q * (d * (depth / -d.z)) + t));
            }
        }
        let o = Organised {
            width: w,
            height: h,
            position: t,
            orientation: q,
            pixels,
            colors: None,
        };
        let p = o.pinhole().unwrap();
        assert!(!p.forward_z);
        for (got, want) in [(p.fx, fx), (p.fy, fy), (p.cx, cx), (p.cy, cy)] {
            assert!((got - want).abs() < 1e-6, "{p:?}");
        }
        assert!(p.residual < 1e-9, "{p:?}");
        let m = o.misses(&p);
        assert_eq!(m.len(), 13 * h);
        // The first miss is pixel (27, 0).
        let want = (q * ray(27.0, 0.0).normalize()).as_vec3();
        assert!((m[0] - want).length() < 1e-6, "{} vs {want}", m[0]);
        let last = (q * ray(39.0, 29.0).normalize()).as_vec3();
        assert!((m[m.len() - 1] - last).length() < 1e-6);
    }
}
