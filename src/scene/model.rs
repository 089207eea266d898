//! The resolved scene: what the integrator renders (camera, lights,
//! materials, splats) in re-centred f32 coordinates, and what loading
//! measured and knew about the exact surfaces.

use crate::resolve::{ShadingMode, SurfaceHit};
use crate::splat::Splat;
use crate::splat::color::ColorField;
use crate::{Error, Result};
use glam::{DVec3, Vec2, Vec3};

/// The widest scene the renderer takes, after re-centring: the squared
/// distances of the ray-disc tests (and a diagonal's worth of `t`) stay
/// finite in f32.
pub const MAX_EXTENT: f32 = 1e18;

/// A surface material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Material {
    /// Lambertian.
    Diffuse {
        /// Albedo.
        color: Vec3,
    },
    /// Lambertian plus Blinn–Phong highlight.
    Phong {
        /// Albedo.
        color: Vec3,
        /// Specular strength.
        specular: f32,
        /// Exponent.
        shininess: f32,
    },
    /// Perfect mirror.
    Mirror {
        /// Reflectance (tint).
        color: Vec3,
    },
    /// Dielectric with Fresnel reflection and refraction.
    Glass {
        /// Transmission tint.
        color: Vec3,
        /// Index of refraction.
        ior: f32,
    },
}

impl Material {
    /// The colour the material multiplies a surface's colour by: the
    /// albedo of a diffuse or Phong material, the tint of a mirror or glass.
    #[must_use]
    pub fn color(&self) -> Vec3 {
        match *self {
            Material::Diffuse { color }
            | Material::Phong { color, .. }
            | Material::Mirror { color }
            | Material::Glass { color, .. } => color,
        }
    }
}

/// A light source.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Point light at `position`, falling off as `1/d²`.
    Point {
        /// Position.
        position: Vec3,
        /// Colour × intensity.
        power: Vec3,
    },
    /// Directional light travelling along `direction`.
    Directional {
        /// Unit direction the light travels.
        direction: Vec3,
        /// Colour × irradiance.
        power: Vec3,
    },
    /// Spherical area light: soft shadows from `samples` stratified points.
    Sphere {
        /// Centre.
        position: Vec3,
        /// Radius.
        radius: f32,
        /// Colour × intensity.
        power: Vec3,
        /// Shadow rays per shading point.
        samples: u32,
    },
}

/// A pinhole camera, resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye.
    pub origin: Vec3,
    /// Unit forward.
    pub forward: Vec3,
    /// Unit right, scaled by the half-width of the image plane at distance 1.
    pub right: Vec3,
    /// Unit up, scaled by the half-height of the image plane at distance 1.
    pub up: Vec3,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// The principal point, pixels, when the camera has intrinsics off the
    /// image's centre; `None`: the centre.
    pub principal: Option<Vec2>,
}

/// A pinhole camera's intrinsics, pixels: focal lengths and principal
/// point (`u = fx·x/z + cx`, `v = fy·y/z + cy` in the camera's frame, `x`
/// right, `y` down, `z` forward), pixel centres at integer `(u, v)` as in
/// OpenCV's and ROS's calibrations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// Focal length along the image's rows, pixels.
    pub fx: f64,
    /// Focal length along its columns, pixels.
    pub fy: f64,
    /// Principal point, pixels from the left edge.
    pub cx: f64,
    /// Principal point, pixels from the top edge.
    pub cy: f64,
}

impl Camera {
    /// Builds a camera looking from `from` at `at`.
    pub fn look_at(
        from: Vec3,
        at: Vec3,
        up: Vec3,
        fov_deg: f32,
        width: u32,
        height: u32,
        spp: u32,
    ) -> Result<Camera> {
        let forward = (at - from)
            .try_normalize()
            .ok_or_else(|| Error::invalid("camera: `from` and `at` coincide"))?;
        let right = forward
            .cross(up)
            .try_normalize()
            .ok_or_else(|| Error::invalid("camera: `up` is parallel to the view direction"))?;
        let true_up = right.cross(forward);
        if !(fov_deg > 0.0 && fov_deg < 180.0) {
            return Err(Error::invalid(format!(
                "camera: fov {fov_deg} must be in (0, 180) degrees"
            )));
        }
        let half_h = (fov_deg.to_radians() * 0.5).tan();
        let half_w = half_h * width as f32 / height as f32;
        Ok(Camera {
            origin: from,
            forward,
            right: right * half_w,
            up: true_up * half_h,
            width,
            height,
            spp,
            principal: None,
        })
    }

    /// As [`Camera::look_at`], the image plane given by a pinhole's
    /// intrinsics instead of a field of view: the ray through pixel
    /// `(cx, cy)` runs along `at - from`, and one through `(cx + fx, cy)`
    /// 45° to its right.
    pub fn look_at_intrinsics(
        from: Vec3,
        at: Vec3,
        up: Vec3,
        k: Intrinsics,
        width: u32,
        height: u32,
        spp: u32,
    ) -> Result<Camera> {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        if !(ok(k.fx) && ok(k.fy) && k.cx.is_finite() && k.cy.is_finite()) {
            return Err(Error::invalid(format!(
                "camera: intrinsics fx {}, fy {} must be finite and positive, cx {}, cy {} finite",
                k.fx, k.fy, k.cx, k.cy
            )));
        }
        let mut c = Camera::look_at(from, at, up, 90.0, width, height, spp)?;
        let (half_w, half_h) = (
            0.5 * f64::from(width) / k.fx,
            0.5 * f64::from(height) / k.fy,
        );
        c.right = c.right.normalize() * half_w as f32;
        c.up = c.up.normalize() * half_h as f32;
        // Our pixel centres sit at +0.5.
        c.principal = Some(Vec2::new((k.cx + 0.5) as f32, (k.cy + 0.5) as f32));
        Ok(c)
    }

    /// The primary ray through image position `(px, py)` in pixels (pixel
    /// centres at `+0.5`; `y` down).
    #[must_use]
    pub fn ray(&self, px: f32, py: f32) -> crate::accel::Ray {
        let (sx, sy) = match self.principal {
            None => (
                2.0 * px / self.width as f32 - 1.0,
                1.0 - 2.0 * py / self.height as f32,
            ),
            Some(c) => (
                (px - c.x) / (0.5 * self.width as f32),
                (c.y - py) / (0.5 * self.height as f32),
            ),
        };
        crate::accel::Ray::new(self.origin, self.forward + self.right * sx + self.up * sy)
    }

    /// The primary rays through the pixel centres of image rows `rows`,
    /// row after row.
    #[must_use]
    pub fn pixel_rays(&self, rows: std::ops::Range<u32>) -> Vec<crate::accel::Ray> {
        rows.flat_map(|y| (0..self.width).map(move |x| self.ray(x as f32 + 0.5, y as f32 + 0.5)))
            .collect()
    }
}

/// Scene-relative tolerances (`docs/DESIGN.md`, "Tolerances"): never
/// absolute constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneScale {
    /// Bounding-box diagonal of the splat set.
    pub diagonal: f32,
    /// Blending window `xi` of §4.3 the backends gather: the widest of the
    /// models' windows ([`Scene::xi_of`]); the resolver trims it to the
    /// nearest splat's model's.
    pub xi: f32,
    /// Self-intersection distance `eps_self` of §3.2 (fig. 9 right).
    pub eps_self: f32,
}

impl SceneScale {
    /// Fractions of the diagonal: `xi = 1e-3 d` (one window for every
    /// splat; a loaded scene measures each model's instead), `eps_self =
    /// 1e-4 d`.
    #[must_use]
    pub fn from_diagonal(diagonal: f32) -> SceneScale {
        SceneScale {
            diagonal,
            xi: 1e-3 * diagonal,
            eps_self: 1e-4 * diagonal,
        }
    }
}

/// Render options, resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Maximum recursion depth.
    pub max_depth: u32,
    /// Shading mode.
    pub shading: ShadingMode,
    /// `xi`, `eps_self` and the diagonal.
    pub scale: SceneScale,
    /// Ambient term.
    pub ambient: f32,
}

/// What loading measured.
#[derive(Clone, Debug, Default)]
pub struct LoadReport {
    /// Seconds spent reading and generating splats.
    pub splat_seconds: f64,
    /// Input points across point models.
    pub input_points: usize,
    /// One line per warning (skipped points and the like).
    pub warnings: Vec<String>,
    /// Coverage of each generated point model (§2.2).
    pub coverage: Vec<f64>,
    /// The exact surface of each model where one is known (mesh models and
    /// shapes), in world space before re-centring: ground truth for
    /// `compare --truth`.
    pub truth: Vec<TruthSource>,
}

/// The exact surface behind one model.
#[derive(Clone, Debug)]
pub enum TruthSource {
    /// A triangle mesh (mesh models), world space.
    Mesh {
        /// The mesh, transformed.
        mesh: crate::io::Mesh,
        /// Material index.
        material: u16,
    },
    /// An analytic sphere.
    Sphere {
        /// Centre, world space.
        center: Vec3,
        /// Radius.
        radius: f32,
        /// Material index.
        material: u16,
    },
    /// A model with no exact surface (a point or splat file), and why.
    Unknown {
        /// 1-based model number.
        model: usize,
        /// What it is.
        what: String,
    },
}

/// The faces of a scene's `triangles` models (issue 57), placed and
/// re-centred with the splats: triangle `i` is hit id `splats.len() + i`
/// ([`Scene::first_triangle`]).
#[derive(Clone, Debug, Default)]
pub struct Triangles {
    /// The faces.
    pub tris: Vec<crate::primitive::Triangle>,
    /// Each face's unit normal, turned to the side its vertex normals face
    /// where it has them (the side a ray meets as its front).
    pub face: Vec<Vec3>,
    /// Each face's unit vertex normals, `[Vec3::ZERO; 3]` where it has none
    /// (it shades with `face`).
    pub normals: Vec<[Vec3; 3]>,
    /// Each face's material index.
    pub material_of: Vec<u16>,
}

/// A loaded scene, re-centred so that its splats' bounding box is centred at
/// the origin (`docs/DESIGN.md`, "Precision": far-from-origin scenes keep their
/// precision).
#[derive(Clone, Debug)]
pub struct Scene {
    /// All splats of all models.
    pub splats: Vec<Splat>,
    /// The triangles of the triangle models (empty in a scene without).
    pub triangles: Triangles,
    /// Each splat's linear colour field (`splat::color`), or empty when no
    /// model carries them (a scene without them pays nothing).
    pub color_fields: Vec<ColorField>,
    /// Material index of each splat.
    pub material_of: Vec<u16>,
    /// Materials.
    pub materials: Vec<Material>,
    /// Shading-mode override of each material (`None`: the scene's mode).
    pub shading_of: Vec<Option<ShadingMode>>,
    /// The blending window `xi` (§4.3) of each material's (model's) splats;
    /// `options.scale.xi`, the window the backends gather, is the widest.
    pub xi_of: Vec<f32>,
    /// Camera.
    pub camera: Camera,
    /// Lights.
    pub lights: Vec<Light>,
    /// Background radiance.
    pub background: Vec3,
    /// Options.
    pub options: RenderOptions,
    /// The re-centring translation subtracted on load, after `shift`
    /// (world = scene + offset + shift).
    pub offset: Vec3,
    /// Where the first model's origin lands (its translation, plus a point
    /// cloud's origin placed by its transform), subtracted in f64 before
    /// re-centring.
    pub shift: DVec3,
    /// Load figures.
    pub load: LoadReport,
}

impl Scene {
    /// The colour of splat `id` at world point `p` on it: its constant
    /// colour, or with a colour field the field's value there
    /// (`ColorField::at`).
    #[must_use]
    pub fn color_at(&self, id: u32, p: Vec3) -> Vec3 {
        let Some(s) = self.splats.get(id as usize) else {
            // A triangle: the material's colour alone.
            return Vec3::ONE;
        };
        match self.color_fields.get(id as usize) {
            Some(f) => f.at(s, p),
            None => s.color,
        }
    }

    /// The hit id of the first triangle: the splats' count.
    #[must_use]
    pub fn first_triangle(&self) -> u32 {
        self.splats.len() as u32
    }

    /// The material of hit `id`, a splat's or a triangle's.
    #[must_use]
    pub fn material_for(&self, id: u32) -> u16 {
        match self.material_of.get(id as usize) {
            Some(&m) => m,
            None => self.triangles.material_of[(id - self.first_triangle()) as usize],
        }
    }

    /// The surface hit of triangle candidate `c` of `ray` (a window of
    /// one): its vertex normals interpolated at the hit's barycentric
    /// `(u, v)` where it has them, else its face normal.
    #[must_use]
    pub fn triangle_hit(&self, c: &crate::accel::Candidate, ray: &crate::accel::Ray) -> SurfaceHit {
        let i = (c.id - self.first_triangle()) as usize;
        let face = self.triangles.face[i];
        let n = self.triangles.normals[i];
        let normal = if n[0] == Vec3::ZERO {
            face
        } else {
            (n[0] * (1.0 - c.u - c.v) + n[1] * c.u + n[2] * c.v)
                .try_normalize()
                .unwrap_or(face)
        };
        let point = ray.at(c.t);
        SurfaceHit {
            id: c.id,
            t: c.t,
            point,
            normal,
            geometric_normal: face,
            front: face.dot(ray.dir) < 0.0,
            blended: 1,
            shadow_origin: point,
        }
    }

    /// The splats' and triangles' bounding box in world coordinates (as
    /// the scene file states them), or `None` without either.
    #[must_use]
    pub fn world_bounds(&self) -> Option<(DVec3, DVec3)> {
        let (lo, hi) = self.splats.iter().map(|s| s.center).chain(self.triangles.tris.iter().flat_map(|t| t.v)).fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), c| (lo.min(c), hi.max(c)),
        );
        let to_world = |v: Vec3| (v + self.offset).as_dvec3() + self.shift;
        (lo.x <= hi.x).then(|| (to_world(lo), to_world(hi)))
    }

    /// True when some material shades its splats with Phong fields (the
    /// only splats a shadow ray can pass, `crate::accel::PassOver`): a
    /// scene without them gives its shadow rays no pass-over rule.
    #[must_use]
    pub fn has_phong(&self) -> bool {
        self.shading_of
            .iter()
            .any(|s| s.unwrap_or(self.options.shading) == ShadingMode::Phong)
    }

    /// The shading mode for a window whose nearest hit is splat `id`: the
    /// model's override, else the scene's.
    #[must_use]
    pub fn shading_for(&self, id: u32) -> ShadingMode {
        let m = self.material_of[id as usize] as usize;
        self.shading_of[m].unwrap_or(self.options.shading)
    }

    /// The blending window for a window whose nearest hit is splat `id`:
    /// its model's `xi`.
    #[must_use]
    pub fn xi_for(&self, id: u32) -> f32 {
        self.xi_of[self.material_of[id as usize] as usize]
    }

    /// Changes the view after loading: the resolution (keeping the vertical
    /// field of view, widening or narrowing the horizontal one; a camera
    /// with intrinsics keeps its image plane, its principal point moved
    /// with the image's size), the samples
    /// per pixel, and the shading mode of the whole scene (which then
    /// replaces every model's own). `None` keeps what the scene file says.
    ///
    /// # Errors
    /// One line when the resolution is outside `1..=32768` or `spp` outside
    /// `1..=4096`; the scene is then unchanged.
    pub fn set_view(
        &mut self,
        width: Option<u32>,
        height: Option<u32>,
        spp: Option<u32>,
        shading: Option<ShadingMode>,
    ) -> Result<()> {
        let c = self.camera;
        let w = width.unwrap_or(c.width);
        let h = height.unwrap_or(c.height);
        let spp = spp.unwrap_or(c.spp);
        if w == 0 || h == 0 || w > 1 << 15 || h > 1 << 15 {
            return Err(Error::invalid(format!(
                "resolution {w}x{h} must be in 1..=32768"
            )));
        }
        if spp == 0 || spp > 4096 {
            return Err(Error::invalid(format!("spp {spp} must be in 1..=4096")));
        }
        match c.principal {
            // Square pixels, the vertical field of view kept.
            None => {
                let half_h = c.up.length();
                let half_w = half_h * w as f32 / h as f32;
                self.camera.right = c.right.normalize() * half_w;
            }
            // A pinhole's: its focal lengths scale with the image, so the
            // image plane stays and the principal point moves with it.
            Some(p) => {
                self.camera.principal = Some(Vec2::new(
                    p.x * w as f32 / c.width as f32,
                    p.y * h as f32 / c.height as f32,
                ));
            }
        }
        self.camera.width = w;
        self.camera.height = h;
        self.camera.spp = spp;
        if let Some(s) = shading {
            self.options.shading = s;
            self.shading_of.iter_mut().for_each(|m| *m = None);
        }
        Ok(())
    }
}

/// Shadow rays see Phong splats as the curved surfaces the resolver shows
/// (`docs/DESIGN.md`, "The backend contract", rule 5): a hit on the disc of
/// a splat shaded [`ShadingMode::Phong`] beyond its field's silhouette
/// (eq. 4; [`crate::resolve::beyond_silhouette_at`]) is passed, as the
/// resolver passes it over in a window; the discs of splats shaded flat or
/// blended are their surfaces.
impl crate::accel::PassOver for Scene {
    #[inline]
    fn passes(&self, id: u32, hit: &crate::primitive::Hit, dir: Vec3) -> bool {
        self.shading_for(id) == ShadingMode::Phong
            && crate::resolve::beyond_silhouette_at(&self.splats[id as usize], hit.u, hit.v, dir)
    }
}

/// Area-weighted vertex normals of a mesh (each face's winding normal,
/// weighted by its area, summed at its corners and normalised; zero at a
/// vertex no face uses): the smooth surface the mesh samples. The exact
/// surface of `compare --truth` and a `smooth` triangles model shade with
/// them.
#[must_use]
pub fn area_weighted_normals(p: &[Vec3], tris: &[[u32; 3]]) -> Vec<Vec3> {
    let mut n = vec![Vec3::ZERO; p.len()];
    for t in tris {
        let [a, b, c] = t.map(|k| p[k as usize]);
        let f = (b - a).cross(c - a); // length = twice the area
        for &k in t {
            n[k as usize] += f;
        }
    }
    n.into_iter().map(Vec3::normalize_or_zero).collect()
}
