//! Scenes: the TOML file format ([`file`]), the scene made for a point
//! cloud given alone ([`cloud`]), loading it into splats,
//! materials, lights and a camera ([`load`]), the resolved scene the
//! integrator renders ([`model`]), and the procedural shapes whose exact
//! surfaces are known ([`shapes`]).
//!
//! Loading shifts a scene placed far from the origin back in f64 and
//! re-centres it on its splats' bounding box, so its splats keep their f32
//! precision; each model keeps its exact surface (meshes and shapes) as
//! ground truth for `compare --truth`.

pub mod cloud;
pub mod file;
pub mod load;
pub mod model;
pub mod num;
pub mod sensor;
pub mod shapes;

pub use file::{
    CameraSpec, LightKind, LightSpec, MaterialKind, MaterialSpec, ModelSpec, RenderSpec, SceneFile,
    ShapeKind, ShapeSpec, SplatSpec, TransformSpec, parse_scene_file, parse_scene_str,
};
pub use load::{
    build_scene, build_scene_reads, load_scene, load_scene_within, scene_camera, scene_lights,
};
pub use model::{
    Camera, Light, LoadReport, Material, RenderOptions, Scene, SceneScale, Triangles,
    TruthSource, area_weighted_normals,
};
