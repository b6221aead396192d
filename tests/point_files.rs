//! Point-cloud files through the public API, `PointCloud::load`: PLY (ascii and both binary byte
//! orders) and XYZ files written into a temporary directory, the two committed under
//! `tests/data/points/`, and the errors that bad ones give — each naming the file, and the line
//! in a text format. Only what the readers decide is checked (positions, given normals, colours,
//! messages) and what the cloud itself refuses; estimated normals and spacing are checked where
//! they are made.

use std::path::{Path, PathBuf};

use glam::Vec3;
use rbvh::points::PointCloud;
use rbvh::Error;

/// A committed file.
fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/points")
        .join(name)
}

/// Writes `bytes` as `name` in `dir`.
fn write(dir: &tempfile::TempDir, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).expect("write a test file");
    path
}

/// A value of a binary PLY body.
#[derive(Clone, Copy)]
enum Value {
    Float(f32),
    UChar(u8),
    Int(i32),
}

/// A binary PLY: `header` (the lines after `format`, `end_header` included), then `values`.
fn binary_ply(big_endian: bool, header: &str, values: &[Value]) -> Vec<u8> {
    let format = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let mut bytes = format!("ply\nformat {format} 1.0\n{header}").into_bytes();
    for value in values {
        let mut le = match *value {
            Value::Float(v) => v.to_le_bytes().to_vec(),
            Value::UChar(v) => vec![v],
            Value::Int(v) => v.to_le_bytes().to_vec(),
        };
        if big_endian {
            le.reverse();
        }
        bytes.extend(le);
    }
    bytes
}

/// The points of `tests/data/points/sphere.ply`: the unit sphere on a Fibonacci lattice.
fn fibonacci_sphere(n: usize) -> Vec<Vec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - y * y).sqrt();
            let phi = i as f64 * golden;
            Vec3::new((phi.cos() * r) as f32, y as f32, (phi.sin() * r) as f32)
        })
        .collect()
}

fn assert_close(got: &[Vec3], expected: &[Vec3], tolerance: f32) {
    assert_eq!(got.len(), expected.len());
    for (i, (g, e)) in got.iter().zip(expected).enumerate() {
        assert!(g.abs_diff_eq(*e, tolerance), "point {i}: {g} != {e}");
    }
}

#[test]
fn committed_binary_sphere_keeps_its_normals() {
    let cloud = PointCloud::load(&data("sphere.ply")).unwrap();
    let expected = fibonacci_sphere(200);
    assert_close(&cloud.positions, &expected, 1e-6);
    // Outward: each normal is its point, the sphere being the unit one about the origin.
    assert_close(&cloud.normals, &expected, 1e-6);
    assert_eq!(cloud.colours, None);
    assert_eq!(cloud.spacing.len(), 200);
}

#[test]
fn committed_xyz_plane_keeps_its_normals() {
    let cloud = PointCloud::load(&data("plane.xyz")).unwrap();
    let expected: Vec<Vec3> = (0..36)
        .map(|k| {
            let (x, y) = ((k % 6) as f32 * 0.2, (k / 6) as f32 * 0.2);
            Vec3::new(x, y, 0.5 * x + 0.25 * y + 1.0)
        })
        .collect();
    assert_close(&cloud.positions, &expected, 1e-5);
    let normal = Vec3::new(-0.5, -0.25, 1.0).normalize();
    assert_close(&cloud.normals, &[normal; 36], 1e-5);
    assert_eq!(cloud.colours, None);
}

#[test]
fn ply_colours_as_bytes_and_as_fractions() {
    let dir = tempfile::tempdir().unwrap();
    let rgba = |r, g, b, a| u32::from_le_bytes([r, g, b, a]);
    let ascii = write(
        &dir,
        "bytes.ply",
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
         property uchar alpha\nend_header\n0 0 0 255 0 0 255\n1 0 0 0 128 0 64\n0 1 0 1 2 3 0\n",
    );
    let cloud = PointCloud::load(&ascii).unwrap();
    assert_eq!(
        cloud.colours,
        Some(vec![
            rgba(255, 0, 0, 255),
            rgba(0, 128, 0, 64),
            rgba(1, 2, 3, 0)
        ])
    );
    let header = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                  property float red\nproperty float green\nproperty float blue\nend_header\n";
    let values: Vec<Value> = [
        [0.0, 0.0, 0.0, 1.0, 0.5, 0.0],
        [1.0, 0.0, 0.0, 2.0, -1.0, 0.2],
        [0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
    ]
    .iter()
    .flatten()
    .map(|&v| Value::Float(v))
    .collect();
    for big_endian in [false, true] {
        let path = write(
            &dir,
            "fractions.ply",
            binary_ply(big_endian, header, &values),
        );
        let cloud = PointCloud::load(&path).unwrap();
        assert_eq!(
            cloud.colours,
            Some(vec![
                rgba(255, 128, 0, 255),
                rgba(255, 0, 51, 255),
                rgba(0, 0, 255, 255)
            ])
        );
    }
}

#[test]
fn a_mesh_ply_is_read_as_its_vertices() {
    let dir = tempfile::tempdir().unwrap();
    let header = "comment a tetrahedron\nelement vertex 4\nproperty float x\nproperty float y\n\
                  property float z\nproperty float confidence\nelement face 4\n\
                  property list uchar int vertex_indices\nend_header\n";
    let corners = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let mut values = vec![];
    for corner in corners {
        values.extend(corner.map(Value::Float));
        values.push(Value::Float(0.9));
    }
    for face in [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] {
        values.push(Value::UChar(3));
        values.extend(face.map(Value::Int));
    }
    for big_endian in [false, true] {
        let path = write(
            &dir,
            "tetrahedron.ply",
            binary_ply(big_endian, header, &values),
        );
        let cloud = PointCloud::load(&path).unwrap();
        assert_eq!(cloud.positions, corners.map(Vec3::from));
        assert_eq!(cloud.colours, None);
        assert_eq!(cloud.normals.len(), 4);
    }
}

#[test]
fn extensions_are_case_insensitive() {
    let dir = tempfile::tempdir().unwrap();
    for (from, to) in [("sphere.ply", "SCAN.PLY"), ("plane.xyz", "plane.XyZ")] {
        let path = write(&dir, to, std::fs::read(data(from)).unwrap());
        let expected = PointCloud::load(&data(from)).unwrap();
        assert_eq!(
            PointCloud::load(&path).unwrap().positions,
            expected.positions
        );
    }
}

/// The line and message of the parse error that loading `path` must give.
fn parse_error(path: &Path) -> (Option<usize>, String) {
    let error = match PointCloud::load(path) {
        Ok(_) => panic!("{} loaded", path.display()),
        Err(e) => e,
    };
    let shown = error.to_string();
    assert!(shown.starts_with(&path.display().to_string()), "{shown}");
    match error {
        Error::Parse {
            path: named,
            line,
            message,
        } => {
            assert_eq!(named, path);
            (line, message)
        }
        other => panic!("expected a parse error, got {other:?}"),
    }
}

#[test]
fn malformed_files_name_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let xyz = write(&dir, "bad.xyz", "# x y z\n0 0 0\n1 0 O\n");
    assert_eq!(parse_error(&xyz), (Some(3), "`O` is not a number".into()));
    let columns = write(&dir, "columns.xyz", "0 0 0\n1 0 0 0 0 1\n");
    let (line, message) = parse_error(&columns);
    assert_eq!(line, Some(2));
    assert!(message.contains("6 values"), "{message}");

    let ascii = write(
        &dir,
        "bad.ply",
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nend_header\n0 0 0\n1 0 0\n0 one 0\n",
    );
    let (line, message) = parse_error(&ascii);
    assert_eq!(line, Some(10));
    assert!(message.contains("`one` is not a float"), "{message}");

    let header =
        "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    let truncated = write(
        &dir,
        "truncated.ply",
        binary_ply(false, header, &[Value::Float(1.0); 7]),
    );
    assert_eq!(
        parse_error(&truncated),
        (None, "the file ends after 2 of 3 vertices".into())
    );
    let not_ply = write(&dir, "image.ply", b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR");
    let (line, message) = parse_error(&not_ply);
    assert_eq!(line, None);
    assert!(message.starts_with("not a PLY file"), "{message}");
    let faces_only = write(
        &dir,
        "faces.ply",
        "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n",
    );
    assert!(parse_error(&faces_only).1.contains("no `vertex` element"));

    let other = write(&dir, "points.txt", "0 0 0\n1 0 0\n0 1 0\n");
    assert!(parse_error(&other).1.contains("expected .ply or .xyz"));
    let missing = dir.path().join("missing.ply");
    match PointCloud::load(&missing) {
        Err(Error::Io { path, .. }) => assert_eq!(path, missing),
        other => panic!("expected an I/O error, got {other:?}"),
    }
}

/// The message of the geometry error that loading `path` must give, checked to name the file.
fn geometry_error(path: &Path) -> String {
    match PointCloud::load(path) {
        Err(Error::InvalidGeometry {
            source_name,
            message,
        }) => {
            assert_eq!(source_name, path.display().to_string());
            message
        }
        other => panic!(
            "{}: expected a geometry error, got {other:?}",
            path.display()
        ),
    }
}

#[test]
fn clouds_that_span_no_surface_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let one = write(&dir, "one.xyz", "1 2 3\n");
    assert!(geometry_error(&one).contains("1 point(s)"));
    let line = write(
        &dir,
        "line.ply",
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
         property float z\nend_header\n0 0 0\n1 1 1\n2 2 2\n3 3 3\n",
    );
    assert!(geometry_error(&line).contains("lie on one line"));
    // Non-finite values are refused where they are read: the line of a text file, the vertex
    // of a binary one.
    let nan = write(&dir, "nan.xyz", "0 0 0\n1 0 0\n0 nan 0\n");
    let e = PointCloud::load(&nan).unwrap_err().to_string();
    assert!(e.contains("nan.xyz:3: `nan` is not a finite number"), "{e}");
    let header =
        "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    let values = [0.0, 0.0, 0.0, 1.0, 0.0, f32::INFINITY, 0.0, 1.0, 0.0].map(Value::Float);
    let infinite = write(&dir, "infinite.ply", binary_ply(true, header, &values));
    assert!(
        geometry_error(&infinite).contains("vertex 1: its position (1.0, 0.0, inf) is not finite")
    );
    let zero_normal = write(
        &dir,
        "zero_normal.xyz",
        "0 0 0 0 0 1\n1 0 0 0 0 0\n0 1 0 0 0 1\n",
    );
    assert!(geometry_error(&zero_normal).contains("point 1 has the normal"));
}
