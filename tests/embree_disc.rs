//! The foundation check: Embree 4 loads, and a user-geometry disc is hit at
//! the analytic distance.

use glam::Vec3;
use splatray::accel::embree::EmbreeBackend;
use splatray::accel::{Backend, CandidateHits, Ray};
use splatray::embree::Device;
use splatray::primitive::Disc;
use splatray::splat::Splat;

#[test]
fn device_reports_embree_4() {
    let device = Device::new().expect("embree device");
    let (major, _, _) = device.version();
    assert_eq!(
        major,
        4,
        "expected Embree 4, device says {:?}",
        device.version()
    );
    let lib = Device::library_path().expect("libembree4 mapped into the process");
    assert!(lib.to_string_lossy().contains("libembree4"));
}

#[test]
fn one_user_geometry_disc_is_hit_at_the_analytic_distance() {
    let device = Device::new().unwrap();
    // A disc of radius 0.5 in the plane z = 2, tilted normal.
    let n = Vec3::new(0.0, 0.3, 1.0);
    let splat = Splat::disc(Vec3::new(0.1, -0.2, 2.0), n, 0.5).unwrap();
    let backend = EmbreeBackend::new(&device, &[splat.disc_geometry()]).unwrap();

    let origin = Vec3::new(0.0, 0.0, -1.0);
    let dir = Vec3::new(0.05, -0.1, 1.0).normalize();
    let ray = Ray::new(origin, dir);
    // Analytic plane distance: t = n·(c - o) / n·d.
    let nn = n.normalize();
    let expected = nn.dot(splat.center - origin) / nn.dot(dir);

    let mut hits = CandidateHits::new(1e-3);
    backend.intersect(&ray, 0.0, f32::INFINITY, &mut hits);
    let hit = hits.nearest().expect("the disc is hit");
    assert_eq!(hit.id, 0);
    let tol = 4.0 * f32::EPSILON * expected;
    assert!(
        (hit.t - expected).abs() <= tol,
        "t: expected {expected}, got {}, tolerance {tol}, diff {}",
        hit.t,
        (hit.t - expected).abs()
    );
    assert!(hit.radial() <= 1.0);
    assert!(backend.occluded(&ray, 0.0, f32::INFINITY));
    // Stop the ray short of the disc: no hit, not occluded.
    backend.intersect(&ray, 0.0, expected * 0.99, &mut hits);
    assert!(hits.is_empty());
    assert!(!backend.occluded(&ray, 0.0, expected * 0.99));
    // Miss beside the disc.
    let miss = Ray::new(origin, Vec3::new(0.5, 0.0, 1.0));
    backend.intersect(&miss, 0.0, f32::INFINITY, &mut hits);
    assert!(hits.is_empty());
    backend.check().expect("no embree errors");
}

#[test]
fn empty_scene_is_valid_and_never_hit() {
    let device = Device::new().unwrap();
    let backend = EmbreeBackend::new(&device, &[] as &[Disc]).unwrap();
    let mut hits = CandidateHits::new(1e-3);
    backend.intersect(
        &Ray::new(Vec3::ZERO, Vec3::Z),
        0.0,
        f32::INFINITY,
        &mut hits,
    );
    assert!(hits.is_empty());
    assert!(!backend.occluded(&Ray::new(Vec3::ZERO, Vec3::Z), 0.0, f32::INFINITY));
}

#[test]
fn bad_device_configuration_is_an_error_not_a_crash() {
    // Embree rejects a malformed configuration value.
    let err = Device::with_config("threads=abc");
    let msg = err
        .expect_err("expected an error from a bad config")
        .to_string();
    assert!(msg.starts_with("embree: "), "{msg}");
}
