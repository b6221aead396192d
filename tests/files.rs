//! The ray and hit files and the image writers, through the public API: exact round trips, the
//! documented byte layout, errors that name the file, and writes that are all or nothing.

use std::path::Path;

use glam::Vec3;
use rbvh::geom::{Hit, Ray};
use rbvh::io::{read_hits, read_rays, write_hits, write_rays};
use rbvh::output::{heatmap, shade, shade_normals, write_exr, write_png, Image};
use rbvh::scene::Light;
use rbvh::Error;

fn words<T: bytemuck::Pod>(records: &[T]) -> Vec<u32> {
    bytemuck::cast_slice(records).to_vec()
}

fn odd_rays() -> Vec<Ray> {
    let f = f32::from_bits;
    vec![
        Ray::new(
            Vec3::new(1.0, -2.0, 3.5),
            Vec3::new(0.0, 0.0, -1.0),
            0.0,
            f32::INFINITY,
        ),
        // Quiet and signalling NaNs with payloads, signed zeros, infinities, tmin > tmax:
        // none of it is the reader's business, and all of it must survive bit for bit.
        Ray {
            origin: [f(0x7fc0_1234), f(0xffa0_0001), -0.0],
            tmin: 5.0,
            dir: [0.0, -0.0, f32::NEG_INFINITY],
            tmax: -1.0,
        },
        Ray {
            origin: [f32::MAX, f32::MIN_POSITIVE, f(1)],
            tmin: -0.0,
            dir: [f(0x7f80_0001), 1e-30, -1e30],
            tmax: f32::NAN,
        },
    ]
}

fn some_hits() -> Vec<Hit> {
    vec![
        Hit {
            t: 2.5,
            normal: [0.0, 1.0, -0.0],
            id: 7,
            instance: 0,
            reserved: [0; 2],
        },
        Hit::MISS,
        Hit {
            t: -0.0,
            normal: [f32::from_bits(0x7fc0_0042), 0.6, 0.8],
            id: 0x0102_0304,
            instance: 1,
            reserved: [u32::MAX, 0xdead_beef],
        },
    ]
}

fn dir_entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn rays_round_trip_bit_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rays.bin");
    let rays = odd_rays();
    write_rays(&path, &rays).unwrap();
    assert_eq!(
        std::fs::metadata(&path).unwrap().len(),
        32 * rays.len() as u64
    );
    assert_eq!(words(&read_rays(&path).unwrap()), words(&rays));
}

#[test]
fn hits_round_trip_bit_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("hits.bin");
    let hits = some_hits();
    write_hits(&path, &hits).unwrap();
    let back = read_hits(&path).unwrap();
    assert_eq!(words(&back), words(&hits));
    assert_eq!(back[1].t, f32::INFINITY);
    assert_eq!(back[1].id, u32::MAX);
}

#[test]
fn ray_layout_is_little_endian_floats_in_documented_order() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rays.bin");
    let fields = [1.0f32, 2.0, 3.0, 0.5, -4.0, 5.0, -6.0, f32::INFINITY];
    let bytes: Vec<u8> = fields.iter().flat_map(|f| f.to_le_bytes()).collect();
    std::fs::write(&path, &bytes).unwrap();
    let rays = read_rays(&path).unwrap();
    let want = Ray::new(
        Vec3::new(1.0, 2.0, 3.0),
        Vec3::new(-4.0, 5.0, -6.0),
        0.5,
        f32::INFINITY,
    );
    assert_eq!(rays, vec![want]);

    write_rays(&path, &[want]).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
}

#[test]
fn hit_layout_is_little_endian_in_documented_order() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("hits.bin");
    let hit = Hit {
        t: 1.5,
        normal: [0.0, 0.0, 1.0],
        id: 0x0102_0304,
        instance: 5,
        reserved: [6, 7],
    };
    let mut bytes = Vec::new();
    for f in [1.5f32, 0.0, 0.0, 1.0] {
        bytes.extend(f.to_le_bytes());
    }
    bytes.extend([4, 3, 2, 1]);
    for r in [5u32, 6, 7] {
        bytes.extend(r.to_le_bytes());
    }
    write_hits(&path, &[hit]).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
    assert_eq!(read_hits(&path).unwrap(), vec![hit]);
}

#[test]
fn truncated_file_is_a_parse_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.rays");
    std::fs::write(&path, [0u8; 33]).unwrap();
    for err in [read_rays(&path).unwrap_err(), read_hits(&path).unwrap_err()] {
        let text = err.to_string();
        match err {
            Error::Parse {
                path: p, message, ..
            } => {
                assert_eq!(p, path);
                assert!(
                    message.contains("33") && message.contains("32"),
                    "{message}"
                );
                assert!(message.contains("truncated"), "{message}");
            }
            other => panic!("expected a parse error, got {other:?}"),
        }
        assert!(text.contains("cut.rays"), "{text}");
    }
}

#[test]
fn missing_file_is_an_io_error_naming_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nowhere.bin");
    for err in [read_rays(&path).unwrap_err(), read_hits(&path).unwrap_err()] {
        assert!(err.to_string().contains("nowhere.bin"), "{err}");
        match err {
            Error::Io { path: p, source } => {
                assert_eq!(p, path);
                assert_eq!(source.kind(), std::io::ErrorKind::NotFound);
            }
            other => panic!("expected an I/O error, got {other:?}"),
        }
    }
}

#[test]
fn empty_file_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.bin");
    std::fs::write(&path, []).unwrap();
    let err = read_rays(&path).unwrap_err();
    assert!(matches!(&err, Error::Parse { .. }), "{err:?}");
    assert!(err.to_string().contains("no rays"), "{err}");
    let err = read_hits(&path).unwrap_err();
    assert!(err.to_string().contains("no hits"), "{err}");
}

#[test]
fn png_is_srgb_encoded_and_right_sized() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("pic.png");
    let image = Image {
        width: 3,
        height: 2,
        pixels: vec![
            Vec3::new(0.5, 0.0, 1.0),
            Vec3::splat(0.2),
            Vec3::new(-1.0, 2.0, f32::NAN),
            Vec3::ZERO,
            Vec3::ONE,
            Vec3::ZERO,
        ],
    };
    write_png(&path, &image).unwrap();
    let back = image::open(&path).unwrap().to_rgb8();
    assert_eq!(back.dimensions(), (3, 2));
    assert_eq!(back.get_pixel(0, 0).0, [188, 0, 255]);
    assert_eq!(back.get_pixel(1, 0).0, [124, 124, 124]);
    assert_eq!(back.get_pixel(2, 0).0, [0, 255, 0]);
    assert_eq!(back.get_pixel(1, 1).0, [255, 255, 255]);
}

#[test]
fn exr_has_colour_depth_and_normal_channels() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("pic.exr");
    let hit = Hit {
        t: 3.25,
        normal: [0.0, 0.6, -0.8],
        id: 4,
        instance: 0,
        reserved: [0; 2],
    };
    let hits = vec![hit, Hit::MISS];
    let image = Image {
        width: 2,
        height: 1,
        pixels: vec![Vec3::new(0.25, 1.5, 0.0), Vec3::new(0.1, 0.2, 0.3)],
    };
    write_exr(&path, &image, &hits).unwrap();

    use exr::prelude::{ReadChannels, ReadLayers};
    let read = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(&path)
        .unwrap();
    let layer = &read.layer_data;
    assert_eq!((layer.size.0, layer.size.1), (2, 1));
    let mut names: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    names.sort();
    assert_eq!(names, ["B", "G", "N.X", "N.Y", "N.Z", "R", "Z"]);
    let channel = |name: &str| -> Vec<f32> {
        let c = layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == name)
            .unwrap();
        match &c.sample_data {
            exr::prelude::FlatSamples::F32(v) => v.clone(),
            other => panic!("channel {name} is not f32: {other:?}"),
        }
    };
    assert_eq!(channel("Z"), [3.25, f32::INFINITY]);
    assert_eq!(channel("R"), [0.25, 0.1]);
    assert_eq!(channel("G"), [1.5, 0.2]);
    assert_eq!(channel("B"), [0.0, 0.3]);
    assert_eq!(channel("N.X"), [0.0, 0.0]);
    assert_eq!(channel("N.Y"), [0.6, 0.0]);
    assert_eq!(channel("N.Z"), [-0.8, 0.0]);
}

#[test]
fn exr_rejects_hits_of_another_size() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("pic.exr");
    let image = Image {
        width: 2,
        height: 1,
        pixels: vec![Vec3::ZERO; 2],
    };
    let err = write_exr(&path, &image, &[Hit::MISS]).unwrap_err();
    assert!(matches!(err, Error::InvalidParameter { .. }), "{err:?}");
    assert!(!path.exists());
}

#[test]
fn shading_checks_lengths() {
    let rays = vec![Ray::new(Vec3::ZERO, Vec3::Z, 0.0, f32::INFINITY); 4];
    let hits = vec![Hit::MISS; 4];
    assert!(shade(&rays, &hits, 2, 2, None).is_ok());
    for (r, h, w, ht) in [(3, 4, 2, 2), (4, 3, 2, 2), (4, 4, 3, 2)] {
        let err = shade(&rays[..r], &hits[..h], w, ht, None).unwrap_err();
        assert!(matches!(err, Error::InvalidParameter { .. }), "{err:?}");
        assert!(shade_normals(&rays[..r], &hits[..h], w, ht).is_err());
    }
    assert!(heatmap(&[1, 2, 3], 2, 2, None).is_err());
}

#[test]
fn shading_lights_front_and_back_faces_alike() {
    let ray = Ray::new(Vec3::new(0.0, 5.0, 0.0), Vec3::NEG_Y, 0.0, f32::INFINITY);
    let facing = Hit {
        t: 5.0,
        normal: [0.0, 1.0, 0.0],
        id: 0,
        instance: 0,
        reserved: [0; 2],
    };
    let away = Hit {
        normal: [0.0, -1.0, 0.0],
        ..facing
    };
    let rays = [ray, ray, ray];
    let hits = [facing, away, Hit::MISS];
    let lit = shade(&rays, &hits, 3, 1, None).unwrap();
    assert!(
        (lit.pixels[0] - Vec3::splat(0.8)).abs().max_element() < 1e-6,
        "{:?}",
        lit.pixels[0]
    );
    assert_eq!(lit.pixels[0], lit.pixels[1]);
    assert_ne!(lit.pixels[2], lit.pixels[0]);

    let down = Light::Directional {
        direction: Vec3::NEG_Y,
    };
    let up = Light::Directional { direction: Vec3::Y };
    let from_above = shade(&rays, &hits, 3, 1, Some(&down)).unwrap();
    let from_below = shade(&rays, &hits, 3, 1, Some(&up)).unwrap();
    assert!(from_above.pixels[0].x > from_below.pixels[0].x);
    let above = Light::Point {
        position: Vec3::new(0.0, 1.0, 0.0),
    };
    assert_eq!(
        shade(&rays, &hits, 3, 1, Some(&above)).unwrap().pixels[0],
        from_above.pixels[0]
    );

    let normals = shade_normals(&rays, &hits, 3, 1).unwrap();
    assert_eq!(
        normals.pixels,
        [
            Vec3::new(0.5, 1.0, 0.5),
            Vec3::new(0.5, 0.0, 0.5),
            Vec3::ZERO
        ]
    );
}

#[test]
fn failed_write_leaves_no_file_and_no_temporary() {
    let dir = tempfile::tempdir().unwrap();
    let image = Image {
        width: 1,
        height: 1,
        pixels: vec![Vec3::ONE],
    };
    let missing = dir.path().join("no-such-dir").join("out.png");
    let err = write_png(&missing, &image).unwrap_err();
    assert!(err.to_string().contains("out.png"), "{err}");
    assert!(matches!(err, Error::Io { .. }), "{err:?}");
    assert!(dir_entries(dir.path()).is_empty());

    // Here the temporary file is written in full and only the final rename fails, because the
    // target is a directory: the temporary must still be cleaned up.
    let target = dir.path().join("taken");
    std::fs::create_dir(&target).unwrap();
    assert!(write_png(&target, &image).is_err());
    assert!(write_rays(&target, &odd_rays()).is_err());
    assert!(write_exr(&target, &image, &[Hit::MISS]).is_err());
    assert_eq!(dir_entries(dir.path()), ["taken"]);
    assert!(dir_entries(&target).is_empty());
}

#[test]
fn writing_over_a_file_replaces_it_wholly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rays.bin");
    let long = vec![Ray::new(Vec3::ONE, Vec3::X, 0.0, 1.0); 100];
    write_rays(&path, &long).unwrap();
    let short = odd_rays();
    write_rays(&path, &short).unwrap();
    assert_eq!(
        std::fs::metadata(&path).unwrap().len(),
        32 * short.len() as u64
    );
    assert_eq!(words(&read_rays(&path).unwrap()), words(&short));
    assert_eq!(dir_entries(dir.path()), ["rays.bin"]);

    let png = dir.path().join("pic.png");
    std::fs::write(&png, vec![0xAB; 100_000]).unwrap();
    let image = Image {
        width: 1,
        height: 1,
        pixels: vec![Vec3::ZERO],
    };
    write_png(&png, &image).unwrap();
    assert!(std::fs::metadata(&png).unwrap().len() < 1000);
    assert_eq!(
        image::open(&png).unwrap().to_rgb8().get_pixel(0, 0).0,
        [0, 0, 0]
    );
}
