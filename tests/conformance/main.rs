//! The conformance suite, in one place: every backend of the registry, for
//! every primitive, against the brute-force oracle (`agreement`), on the
//! intersector's hard cases (`hard_cases`), and the candidate window's
//! independence of the order hits arrive in (`window`). A backend added to
//! `accel::registry` runs all of it with no edit here.

#[path = "../common/mod.rs"]
mod common;

mod agreement;
mod departure;
mod hard_cases;
mod hostile_rays;
mod window;
