//! Surface splats: oriented discs and ellipses with a linear "Phong" normal
//! field (report §2.1 and §4.1).

pub use crate::data::{NormalField, PointCloud, Scans, Splat, Viewpoints};
pub use crate::geometry::tangent_frame;
pub use crate::primitive::{ClippedDisc, Disc};

pub mod clip;
pub mod color;
pub mod denoise;
pub mod field;
pub mod fit;
pub(crate) mod frame;
mod generate;
pub mod grow;
pub mod holes;
pub mod knn;
pub mod lean;
pub mod normals;
mod options;
pub mod outliers;
pub mod partners;
pub mod planes;
mod rim;
pub mod standoff;
pub mod thin;

/// The robust centre (per-axis medians) the readers put a cloud's origin at,
/// for clouds made in memory (the Python package's arrays).
pub use crate::data::robust_centre_size;
pub use clip::{Clip, ClipLine};
pub use generate::{
    Creases, GenerateError, HOLLOW_LARGE, LeanMode, LeanReport, NOISE_PROJECT, Skipped, SplatParams,
    SplatReport,
    StageSeconds, count_on_splats, coverage, generate, generate_with_progress, hollow_large,
    viewpoints_of,
};
pub(crate) use generate::{Grown, generate_stages};
pub use holes::{COVER_SPACINGS, UNCOVERED_LARGE, covered_share, on_splat, uncovered_large};
pub use options::GenerationOptions;
