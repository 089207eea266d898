//! The data splatray holds: point clouds (positions, normals, colours,
//! scanners) and splats (discs with normal, colour and clip fields). They
//! sit below everything that reads, makes, traces or writes them: `io`
//! reads and writes them, `splat` generates splats from clouds, `accel`
//! and `render` trace splats, and none of those needs another to name the
//! types.

mod cloud;
mod robust;
mod splat;

pub use cloud::{FACING_AWAY_COS, FACING_AWAY_MAX, PointCloud, Scans, Viewpoints};
pub use robust::{WIDENED_SHARE, robust_centre_size, trimmed_diagonal, trimmed_diagonal_of};
pub use splat::{ColorField, NormalField, Splat};
