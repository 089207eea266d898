//! Readers and writers on the bundled scans and on hand-made bad inputs.

mod common;

use common::{data, scratch};

use glam::{DVec3, Vec2, Vec3};
use splatray::io::{
    COLOR_FIELD_PROPS, IoErrorKind, PointCloud, SplatSet, encode_splats_with, lzf_decompress,
    read_mesh, read_points, read_splats, sample_mesh, write_points, write_splats,
};
use splatray::splat::color::ColorField;
use splatray::splat::{NormalField, Splat};
use std::path::{Path, PathBuf};

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// The error of a read that must fail (without printing a whole cloud).
#[track_caller]
fn must_fail<T>(r: Result<T, splatray::io::IoError>) -> splatray::io::IoError {
    match r {
        Ok(_) => panic!("expected an error, the read succeeded"),
        Err(e) => e,
    }
}

fn skipped(c: &PointCloud, reason: &str) -> usize {
    c.skipped
        .iter()
        .filter(|(r, _)| r == reason)
        .map(|(_, n)| *n)
        .sum()
}

#[test]
fn bunny_mesh_binary_le_reads_as_points_and_mesh() {
    let c = read_points(&data("bunny-mesh.ply")).unwrap();
    assert_eq!(c.len(), 34_835);
    assert!(c.normals.is_none() && c.colors.is_none());
    assert!((0..c.len()).all(|i| c.world(i).abs().max_element() <= 1.0 + 1e-5));
    let m = read_mesh(&data("bunny-mesh.ply")).unwrap();
    assert_eq!(m.positions.len(), 34_835);
    assert_eq!(m.triangles.len(), 69_666);
    assert!(
        m.triangles
            .iter()
            .flatten()
            .all(|&i| (i as usize) < m.positions.len())
    );
}

#[test]
fn bunny_scan_ascii_with_extra_properties_and_faces() {
    let c = read_points(&data("bunny-scan.ply")).unwrap();
    assert_eq!(c.len(), 1_889);
    assert!(c.normals.is_none());
    // First vertex line: -0.0369122 0.127512 0.00276757 0.850855 0.5
    assert!((c.world(0) - DVec3::new(-0.0369122, 0.127512, 0.00276757)).length() < 1e-6);
    let m = read_mesh(&data("bunny-scan.ply")).unwrap();
    assert_eq!(m.triangles.len(), 3_851);
}

#[test]
fn parasaurolophus_keeps_its_non_unit_normals() {
    let c = read_points(&data("parasaurolophus_6700.ply")).unwrap();
    assert_eq!(c.len(), 6_700);
    let n = c.normals.as_ref().expect("normals");
    assert!((n[0] - Vec3::new(0.795545, -0.849531, -2.42915)).length() < 1e-5);
    assert!(n.iter().any(|v| (v.length() - 1.0).abs() > 0.1));
}

#[test]
fn milk_pcd_binary_compressed_with_rgba() {
    let c = read_points(&data("milk.pcd")).unwrap();
    assert_eq!(c.len() + c.skipped_total(), 12_575);
    let col = c.colors.as_ref().expect("colours");
    assert!(
        col.iter()
            .all(|v| v.min_element() >= 0.0 && v.max_element() <= 1.0)
    );
    // The file packs 0x000000ff (0xAARRGGBB) for every point: pure blue.
    assert!(col.iter().all(|v| *v == Vec3::Z), "{:?}", col[0]);
    let lo = c.positions.iter().fold(Vec3::MAX, |a, p| a.min(*p));
    let hi = c.positions.iter().fold(Vec3::MIN, |a, p| a.max(*p));
    let size = hi - lo;
    assert!(
        size.max_element() > 0.05 && size.max_element() < 5.0,
        "{size}"
    );
}

#[test]
fn lamppost_pcd_ascii() {
    let c = read_points(&data("lamppost-ascii.pcd")).unwrap();
    assert_eq!(c.len(), 1_771);
    assert!((c.world(1) - DVec3::new(-10.015625, 0.0, 0.042999268)).length() < 1e-6);
}

#[test]
fn ply_binary_big_endian_and_float_and_u8_colours() {
    let dir = scratch("be");
    let mut be = b"ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nproperty int extra\nend_header\n".to_vec();
    for (p, c) in [
        ([1.0f32, 2.0, 3.0], [255u8, 0, 0]),
        ([4.0, 5.0, 6.0], [0, 0, 255]),
    ] {
        for v in p {
            be.extend_from_slice(&v.to_be_bytes());
        }
        be.extend_from_slice(&c);
        be.extend_from_slice(&7i32.to_be_bytes());
    }
    let c = read_points(&write(&dir, "be.ply", &be)).unwrap();
    // Re-centred on the per-axis medians (of two points, their midpoint).
    assert_eq!(c.origin, DVec3::new(2.5, 3.5, 4.5));
    assert_eq!(c.positions, vec![Vec3::splat(-1.5), Vec3::splat(1.5)]);
    assert_eq!(c.colors.unwrap(), vec![Vec3::X, Vec3::Z]);
    let ascii = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\nproperty float red\nproperty float green\nproperty float blue\nend_header\n1 2 3 1 0 0.5\n";
    let c = read_points(&write(&dir, "f.ply", ascii)).unwrap();
    let col = c.colors.unwrap()[0];
    assert_eq!((col.x, col.y), (1.0, 0.0));
    assert!(
        (col.z - 0.214).abs() < 0.01,
        "sRGB 0.5 is linear ~0.214, got {}",
        col.z
    );
}

#[test]
fn quads_are_fan_triangulated() {
    let dir = scratch("quad");
    let ply = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar uint vertex_index\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
    let m = read_mesh(&write(&dir, "q.ply", ply)).unwrap();
    assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    let bad = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n3 0 1 2\n";
    let e = must_fail(read_mesh(&write(&dir, "bad.ply", bad)));
    assert!(matches!(e.kind(), IoErrorKind::Data(_)), "{e}");
}

#[test]
fn xyz_with_and_without_normals() {
    let dir = scratch("xyz");
    let c = read_points(&write(
        &dir,
        "a.xyz",
        b"# comment\n1 2 3\n4,5,6\n\n7\t8 9\n",
    ))
    .unwrap();
    assert_eq!(c.len(), 3);
    assert!(c.normals.is_none());
    let c = read_points(&write(&dir, "b.txt", b"1 2 3 0 0 1\n4 5 6 0 1 0\n")).unwrap();
    assert_eq!(c.normals.unwrap()[1], Vec3::Y);
    let e = must_fail(read_points(&write(&dir, "c.xyz", b"1 2 3\n4 5\n")));
    assert!(e.to_string().contains("line 2"), "{e}");
    // Sniffed without an extension.
    let c = read_points(&write(&dir, "noext", b"1 2 3\n4 5 6\n")).unwrap();
    assert_eq!(c.len(), 2);
}

#[test]
fn formats_are_sniffed_when_the_extension_says_nothing() {
    let dir = scratch("sniff");
    for (src, name, n) in [
        ("milk.pcd", "milk.bin", 12_575),
        ("bunny-scan.ply", "scan.dat", 1_889),
        ("lamppost-ascii.pcd", "lamp", 1_771),
    ] {
        let p = write(&dir, name, &std::fs::read(data(src)).unwrap());
        let c = read_points(&p).unwrap();
        assert_eq!(c.len() + c.skipped_total(), n, "{name}");
    }
}

#[test]
fn non_finite_points_are_skipped_and_counted() {
    let dir = scratch("nan");
    let c = read_points(&write(&dir, "n.xyz", b"1 2 3\nnan 0 0\n0 inf 0\n4 5 6\n")).unwrap();
    assert_eq!(c.len(), 2);
    assert_eq!(skipped(&c, "non-finite coordinates"), 2);
    let e = must_fail(read_points(&write(&dir, "all.xyz", b"nan 0 0\n")));
    assert!(matches!(e.kind(), IoErrorKind::NoPoints(_)), "{e}");
    assert!(e.to_string().contains("non-finite"), "{e}");
}

fn assert_one_line_naming(e: &impl std::fmt::Display, file: &Path) {
    let s = e.to_string();
    assert!(!s.contains('\n'), "not one line: {s:?}");
    assert!(
        s.contains(&file.display().to_string()),
        "does not name the file: {s}"
    );
}

#[test]
fn empty_unknown_and_missing_files_are_clear_errors() {
    let dir = scratch("empty");
    let p = write(&dir, "e.ply", b"");
    let e = must_fail(read_points(&p));
    assert!(matches!(e.kind(), IoErrorKind::Empty));
    assert_one_line_naming(&e, &p);
    let p = write(&dir, "u.bin", b"\x00\x01\x02garbage\n");
    let e = must_fail(read_points(&p));
    assert!(matches!(e.kind(), IoErrorKind::UnknownFormat), "{e}");
    assert_one_line_naming(&e, &p);
    let p = dir.join("missing.ply");
    let e = must_fail(read_points(&p));
    assert!(matches!(e.kind(), IoErrorKind::Io(_)));
    assert_one_line_naming(&e, &p);
    let p = write(
        &dir,
        "h.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float q\nend_header\n1\n",
    );
    let e = must_fail(read_points(&p));
    assert!(matches!(e.kind(), IoErrorKind::Header(_)), "{e}");
}

#[test]
fn truncated_binary_ply_and_lying_headers() {
    let dir = scratch("trunc");
    let full = std::fs::read(data("bunny-mesh.ply")).unwrap();
    let p = write(&dir, "t.ply", &full[..300_000]);
    let e = must_fail(read_points(&p));
    assert!(matches!(e.kind(), IoErrorKind::Truncated(_)), "{e}");
    assert_one_line_naming(&e, &p);
    let e = must_fail(read_mesh(&write(&dir, "half.ply", &full[..full.len() / 2])));
    assert!(matches!(e.kind(), IoErrorKind::Truncated(_)), "{e}");
    // A header promising ~10^18 points over 12 bytes: fails without allocating.
    let mut lie = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    lie.extend_from_slice(&[0u8; 12]);
    let e = must_fail(read_points(&write(&dir, "lie.ply", &lie)));
    assert!(matches!(e.kind(), IoErrorKind::Truncated(_)), "{e}");
    let lie = b"ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
    let e = must_fail(read_points(&write(&dir, "lie2.ply", lie)));
    assert!(matches!(e.kind(), IoErrorKind::Truncated(_)), "{e}");
    let pcd = b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4000000000\nHEIGHT 1\nPOINTS 4000000000\nDATA binary\n\x00\x00\x00\x00";
    let e = must_fail(read_points(&write(&dir, "lie.pcd", pcd)));
    assert!(matches!(e.kind(), IoErrorKind::Truncated(_)), "{e}");
    let pcd = b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA ascii\n1 2 3\n";
    let e = must_fail(read_points(&write(&dir, "short.pcd", pcd)));
    assert!(matches!(e.kind(), IoErrorKind::Truncated(_)), "{e}");
    // milk.pcd ends in zero padding after its compressed block (as PCL
    // writes it), so cut into the block itself.
    let milk = std::fs::read(data("milk.pcd")).unwrap();
    let e = must_fail(read_points(&write(
        &dir,
        "milk.pcd",
        &milk[..milk.len() / 2],
    )));
    assert!(matches!(e.kind(), IoErrorKind::Truncated(_)), "{e}");
}

#[test]
fn pcd_binary_with_normals_and_rgb() {
    let dir = scratch("pcdbin");
    let mut b = b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z normal_x normal_y normal_z rgb\nSIZE 4 4 4 4 4 4 4\nTYPE F F F F F F F\nCOUNT 1 1 1 1 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA binary\n".to_vec();
    for i in 0..2 {
        for v in [i as f32, 1.0, 2.0, 0.0, 0.0, 1.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&0x00ff_0000u32.to_le_bytes());
    }
    let c = read_points(&write(&dir, "b.pcd", &b)).unwrap();
    assert_eq!(c.world(1), DVec3::new(1.0, 1.0, 2.0));
    assert_eq!(c.normals.unwrap()[0], Vec3::Z);
    assert_eq!(c.colors.unwrap()[0], Vec3::X);
}

#[test]
fn lzf_rejects_corrupt_streams() {
    assert_eq!(
        lzf_decompress(&[2, b'x', b'y', b'z', 1 << 5, 2], 6).unwrap(),
        b"xyzxyz"
    );
    assert!(lzf_decompress(&[1 << 5, 200], 3).is_err());
}

#[test]
fn clipped_splats_round_trip_bit_for_bit_and_only_they_add_properties() {
    use splatray::splat::{Clip, ClipLine};
    let dir = scratch("clipped-splats");
    let line = |t: f32, d: f32| ClipLine {
        a: t.cos(),
        b: t.sin(),
        d,
    };
    let mut splats: Vec<Splat> = (0..30)
        .map(|i| {
            let t = i as f32 * 0.61;
            let mut s =
                Splat::disc(Vec3::new(t, t.sin(), 1.0), Vec3::new(t, 1.0, 0.3), 0.2).unwrap();
            s.radii = Vec2::new(0.2, 0.1 + t * 0.01);
            s
        })
        .collect();
    let origin = DVec3::new(1e6 + 0.25, -3.5, 7.0);
    let whole = dir.join("whole.ply");
    write_splats(&whole, &splats, origin).unwrap();
    let whole_bytes = std::fs::read(&whole).unwrap();
    // No clipped splat: no clip property, the record size of before.
    assert!(!String::from_utf8_lossy(&whole_bytes).contains("clip_"));
    for (i, s) in splats.iter_mut().enumerate() {
        let t = i as f32 * 0.9;
        s.clip = match i % 3 {
            0 => Clip::NONE,
            1 => Clip::one(line(t, 0.1 * t.sin())),
            _ => Clip::two(line(t, -0.3), line(t + 1.7, 1e-7 * t)),
        };
    }
    let p = dir.join("clipped.ply");
    write_splats(&p, &splats, origin).unwrap();
    let back = read_splats(&p).unwrap();
    assert_eq!(back.splats, splats);
    let bytes = std::fs::read(&p).unwrap();
    let header: usize = splatray::io::CLIP_PROPS
        .iter()
        .map(|n| "property float \n".len() + n.len())
        .sum();
    assert_eq!(bytes.len(), whole_bytes.len() + 30 * 24 + header);
    // With colour fields too: both read back.
    let fields: Vec<ColorField> = (0..30)
        .map(|i| ColorField {
            du: Vec3::new(0.1, i as f32 * 1e-3, 0.0),
            dv: Vec3::splat(-0.01),
        })
        .collect();
    let q = dir.join("both.ply");
    std::fs::write(
        &q,
        encode_splats_with(&q, &splats, Some(&fields), origin).unwrap(),
    )
    .unwrap();
    let back = read_splats(&q).unwrap();
    assert_eq!((back.splats, back.color_fields), (splats.clone(), fields));
    // A second line without a first, and a non-finite line, are one-line
    // errors naming the file.
    let body = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let rec = splatray::io::splat_row_bytes(false, true);
    let at = |k: usize| body + 21 * 4 + 4 * k; // splat 0, clip value k
    let mut lone = bytes.clone();
    lone[at(3)..at(4)].copy_from_slice(&1.0f32.to_le_bytes());
    let r = dir.join("lone.ply");
    std::fs::write(&r, &lone).unwrap();
    let e = must_fail(read_splats(&r));
    assert!(e.to_string().contains("splat 0: clip line"), "{e}");
    assert_one_line_naming(&e, &r);
    let mut nan = bytes.clone();
    nan[rec + at(2)..rec + at(3)].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(&r, &nan).unwrap();
    let e = must_fail(read_splats(&r));
    assert!(
        e.to_string().contains("splat 1: non-finite clip line"),
        "{e}"
    );
    // A clip line the writer cannot store is refused, nothing written.
    splats[4].clip = Clip::one(line(0.0, f32::INFINITY));
    let e = must_fail(write_splats(&dir.join("bad.ply"), &splats, origin));
    assert!(e.to_string().contains("splat 4 has a clip line"), "{e}");
    assert!(!dir.join("bad.ply").exists());
}

#[test]
fn splat_files_round_trip_losslessly_and_atomically() {
    let dir = scratch("splats");
    let mut splats = Vec::new();
    for i in 0..50 {
        let t = i as f32 * 0.37;
        let mut s = Splat::disc(
            Vec3::new(t.sin(), t.cos(), t),
            Vec3::new(t, 1.0, -t),
            0.1 + t,
        )
        .unwrap();
        s.radii = Vec2::new(0.1 + t, 0.05 + t * 0.5);
        s.v_axis = s.normal.cross(s.u_axis);
        s.color = Vec3::new(0.1, 0.2, t / 20.0);
        s.field = NormalField {
            xc: t * 0.01,
            yc: -t,
            alpha: 1.0 / (1.0 + t),
            beta: t.sqrt(),
        };
        splats.push(s);
    }
    let p = dir.join("s.ply");
    // An origin that only f64 holds: it comes back bit for bit.
    let origin = DVec3::new(512_345.678_901_234, 4_012_345.123_456_789, -0.1);
    write_splats(&p, &splats, origin).unwrap();
    assert_eq!(
        read_splats(&p).unwrap(),
        SplatSet {
            splats: splats.clone(),
            origin,
            color_fields: Vec::new(),
        }
    );
    let leftovers: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert_eq!(leftovers.len(), 1, "only the output remains");
    // Writing into a missing folder fails cleanly and leaves nothing.
    let e = must_fail(write_splats(
        &dir.join("no/such/dir/s.ply"),
        &splats,
        DVec3::ZERO,
    ));
    assert_one_line_naming(&e, &dir.join("no/such/dir/s.ply"));
    // A point cloud is not a splat file.
    let e = must_fail(read_splats(&data("bunny-scan.ply")));
    assert!(e.to_string().contains("not a splat file"), "{e}");
    // With linear colour fields: six more float properties, read back bit
    // for bit; the file without them is unchanged in size and reads none.
    let fields: Vec<ColorField> = (0..splats.len())
        .map(|i| ColorField {
            du: Vec3::new(0.1, -0.2, i as f32 * 1e-3),
            dv: Vec3::new(-(i as f32) * 0.7e-3, 0.05, 0.0),
        })
        .collect();
    let q = dir.join("fields.ply");
    let bytes = encode_splats_with(&q, &splats, Some(&fields), origin).unwrap();
    std::fs::write(&q, &bytes).unwrap();
    let back = read_splats(&q).unwrap();
    assert_eq!(
        (back.splats, back.color_fields),
        (splats.clone(), fields.clone())
    );
    let plain = std::fs::metadata(&p).unwrap().len() as usize;
    let header: usize = COLOR_FIELD_PROPS
        .iter()
        .map(|n| "property float \n".len() + n.len())
        .sum();
    assert_eq!(bytes.len(), plain + splats.len() * 24 + header);
    // A field value that is not finite is refused in one line.
    let mut broken = bytes.clone();
    let body = broken
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    broken[body + 21 * 4..body + 22 * 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let r = dir.join("broken.ply");
    std::fs::write(&r, &broken).unwrap();
    let e = must_fail(read_splats(&r));
    assert!(
        e.to_string().contains("splat 0: colour field value NaN"),
        "{e}"
    );
    assert_one_line_naming(&e, &r);
    // Fields that do not match the splats are refused, nothing written.
    let e = must_fail(encode_splats_with(&q, &splats, Some(&fields[1..]), origin));
    assert!(
        e.to_string().contains("49 colour fields for 50 splats"),
        "{e}"
    );
}

#[test]
fn sampling_is_deterministic_area_uniform_with_face_normals() {
    let m = read_mesh(&data("bunny-mesh.ply")).unwrap();
    let a = sample_mesh(&m, 20_000, 0.0, 7);
    let b = sample_mesh(&m, 20_000, 0.0, 7);
    let c = sample_mesh(&m, 20_000, 0.0, 8);
    assert_eq!(a, b);
    assert_ne!(a.positions, c.positions);
    let n = a.normals.as_ref().unwrap();
    assert!(n.iter().all(|v| (v.length() - 1.0).abs() < 1e-4));
    // Area uniform: a unit square of two unequal-looking triangles splits
    // its samples evenly.
    let sq = splatray::io::Mesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        origin: glam::DVec3::ZERO,
    };
    let s = sample_mesh(&sq, 40_000, 0.0, 1);
    let below = s.positions.iter().filter(|p| p.y < p.x).count() as f64 / 40_000.0;
    assert!((below - 0.5).abs() < 0.01, "{below}");
    let left = s.positions.iter().filter(|p| p.x < 0.5).count() as f64 / 40_000.0;
    assert!((left - 0.5).abs() < 0.01, "{left}");
    // Points written and read back.
    let dir = scratch("sample");
    write_points(&dir.join("p.ply"), &a).unwrap();
    let back = read_points(&dir.join("p.ply")).unwrap();
    assert_eq!(back.len(), a.len());
    // Re-centred on read: each position within one f32 rounding of the
    // offset from the new origin (the bunny is within 1 of zero).
    assert_ne!(back.origin, DVec3::ZERO);
    for i in 0..a.len() {
        let d = (back.world(i) - a.world(i)).abs().max_element();
        assert!(d <= f64::from(f32::EPSILON), "point {i} moved by {d}");
    }
    assert_eq!(back.normals, a.normals);
}

/// What other tools read: `x y z nx ny nz` first, `radius`, and the colour
/// as 8-bit sRGB `uchar red green blue` (MeshLab takes only that; Open3D's
/// standard reader divides float colours by 255); this reader keeps the
/// linear floats. A MeshLab-style file of discs with `uchar` colours reads
/// its colours back through sRGB.
#[test]
fn splat_files_carry_srgb_uchar_colours_other_tools_read() {
    let dir = scratch("splats-srgb");
    let mut s = Splat::disc(Vec3::ZERO, Vec3::Z, 0.5).unwrap();
    s.color = Vec3::new(0.0, 0.215_860_53, 1.0); // sRGB 0, 128, 255
    let p = dir.join("s.ply");
    write_splats(&p, &[s], DVec3::ZERO).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = String::from_utf8_lossy(&bytes[..end]);
    let props: Vec<&str> = header
        .lines()
        .filter(|l| l.starts_with("property"))
        .collect();
    assert_eq!(
        props[..6],
        [
            "property float x",
            "property float y",
            "property float z",
            "property float nx",
            "property float ny",
            "property float nz"
        ]
    );
    assert_eq!(props[6], "property float radius");
    assert_eq!(
        props[props.len() - 3..],
        [
            "property uchar red",
            "property uchar green",
            "property uchar blue"
        ]
    );
    assert_eq!(bytes[bytes.len() - 3..], [0, 128, 255]);
    assert_eq!(read_splats(&p).unwrap().splats[0].color, s.color);
    // Discs with only uchar colours.
    let mut text = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty float radius\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n".to_vec();
    for v in [0.0f32, 0.0, 0.0, 0.0, 0.0, 1.0, 0.5] {
        text.extend_from_slice(&v.to_le_bytes());
    }
    text.extend_from_slice(&[0, 128, 255]);
    let q = dir.join("meshlab.ply");
    std::fs::write(&q, text).unwrap();
    let c = read_splats(&q).unwrap().splats[0].color;
    assert!((c - s.color).abs().max_element() < 1e-4, "{c}");
}

/// LAS and LAZ stream from disk a batch at a time (tiled generation reads
/// them so) with the points, georeferenced positions and colours a whole
/// read gives; a LAZ cut short is one error, not a panic.
#[test]
fn las_and_laz_stream_as_they_read() {
    for name in ["autzen.las", "32-1-472-150-76.laz"] {
        let path = data(name);
        let whole = splatray::io::read_points(&path).unwrap();
        let mut world: Vec<DVec3> = Vec::new();
        let mut colors: Vec<Vec3> = Vec::new();
        let info = splatray::io::stream_points(&path, |b| {
            world.extend_from_slice(b.world);
            if let Some(c) = b.colors {
                colors.extend_from_slice(c);
            }
            Ok(())
        })
        .unwrap();
        assert!(info.streamed, "{name} was read whole");
        assert_eq!(world.len(), whole.len(), "{name}");
        assert_eq!(info.points as usize, whole.len());
        // The whole read keeps f32 offsets from its origin: equal to their
        // rounding.
        let extent = world.iter().fold(0.0f64, |m, p| {
            m.max((*p - whole.origin).abs().max_element())
        });
        let tol = extent * 2.0 * f64::from(f32::EPSILON);
        for (p, q) in world.iter().zip(&whole.positions) {
            let d = (*p - (whole.origin + q.as_dvec3())).abs().max_element();
            assert!(d <= tol, "{name}: {p} against {q} (+origin), {d} > {tol}");
        }
        assert_eq!(info.colors, whole.colors.is_some(), "{name}");
        if let Some(c) = &whole.colors {
            assert_eq!(&colors, c, "{name}");
        }
    }
    let dir = scratch("las-stream-cut");
    let bytes = std::fs::read(data("32-1-472-150-76.laz")).unwrap();
    let cut = write(&dir, "cut.laz", &bytes[..bytes.len() * 2 / 3]);
    let e = splatray::io::stream_points(&cut, |_| Ok(())).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("cut.laz") && !msg.contains('\n'), "{msg}");
}
