//! Cross-validation: the same scene through two backends, ray for ray and
//! image for image (`docs/DESIGN.md`, "The backend contract").

pub mod causes;
pub mod compare;
pub mod holdout;
pub mod photo;
pub mod scan_check;
pub mod sweep;
pub mod truth;
