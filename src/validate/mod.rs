//! Cross-validation: the same scene through two backends, ray for ray and
//! image for image (DESIGN §2, §4).

pub mod compare;
pub mod sweep;
pub mod truth;
