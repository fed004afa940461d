//! EXR/PNG files on disk: round trips, other renderers' channel names, the shared
//! Mitsuba reference, and clear errors.

use filtrace_core::Image;
use filtrace_io::{read_exr, write_exr, write_image, write_png, ExrImage, IoError, TonemapParams};
use std::path::PathBuf;

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("filtrace-io-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A deterministic image whose every value differs (so swapped channels are caught).
fn ramp(w: usize, h: usize, c: usize, seed: f32) -> Image {
    let data = (0..w * h * c).map(|i| seed + i as f32 * 0.37 - (i % 7) as f32).collect();
    Image::from_vec(w, h, c, data).unwrap()
}

const LAYERS: [(&str, &[&str]); 8] = [
    ("", &["R", "G", "B"]),
    ("direct", &["R", "G", "B"]),
    ("indirect", &["R", "G", "B"]),
    ("albedo", &["R", "G", "B"]),
    ("normal", &["X", "Y", "Z"]),
    ("position", &["X", "Y", "Z"]),
    ("depth", &["Z"]),
    ("variance", &["R", "G", "B"]),
];

#[test]
fn round_trip_of_all_layers_is_exact() {
    let (w, h) = (13, 7);
    let mut exr = ExrImage::new(w, h);
    let mut originals = Vec::new();
    for (i, (layer, names)) in LAYERS.iter().enumerate() {
        let im = ramp(w, h, names.len(), i as f32 * 100.0);
        exr.insert(layer, names, &im).unwrap();
        originals.push(im);
    }
    let filtered = ramp(w, h, 3, -50.0);
    exr.insert("filtered", &["R", "G", "B"], &filtered).unwrap();
    let importance = ramp(w, h, 1, 7.0);
    exr.insert("importance", &["Y"], &importance).unwrap();

    let dir = temp_dir("roundtrip");
    let path = dir.join("all.exr");
    write_exr(&path, &exr).unwrap();
    let back = read_exr(&path).unwrap();
    assert_eq!((back.width(), back.height()), (w, h));
    assert_eq!(back.channels().len(), 3 * 7 + 1 + 3 + 1);
    let canonical = ["color", "direct", "indirect", "albedo", "normal", "position", "depth", "variance"];
    for (name, original) in canonical.iter().zip(&originals) {
        assert_eq!(back.layer(&[name]).as_ref(), Some(original), "layer {name}");
    }
    assert_eq!(back.layer(&["filtered"]), Some(filtered));
    assert_eq!(back.layer(&["importance"]), Some(importance));
    assert!(back.channel("depth.Z").is_some());
    assert!(back.channel("normal.X").is_some());
    assert!(back.layer(&["nonexistent"]).is_none());
    // Fallback order: the first name that exists wins.
    assert_eq!(back.layer(&["nonexistent", "albedo"]).as_ref(), Some(&originals[3]));
    std::fs::remove_dir_all(&dir).ok();
}

/// Writes planes with exactly the given channel names in f16 (as Blender does).
fn write_foreign(path: &std::path::Path, w: usize, h: usize, names: &[&str]) {
    use exr::prelude::*;
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = names
        .iter()
        .enumerate()
        .map(|(k, n)| {
            let v = (0..w * h).map(|i| f16::from_f32(k as f32 + i as f32 * 0.25)).collect();
            AnyChannel::new(*n, FlatSamples::F16(v))
        })
        .collect();
    let layer =
        Layer::new((w, h), LayerAttributes::default(), Encoding::FAST_LOSSLESS, AnyChannels::sort(list));
    Image::from_layer(layer).write().to_file(path).unwrap();
}

#[test]
fn blender_and_mitsuba_channel_names_are_understood() {
    let dir = temp_dir("aliases");
    let (w, h) = (4, 3);
    let blender = dir.join("blender.exr");
    let bnames = [
        "ViewLayer.Combined.R",
        "ViewLayer.Combined.G",
        "ViewLayer.Combined.B",
        "ViewLayer.Combined.A",
        "ViewLayer.Normal.X",
        "ViewLayer.Normal.Y",
        "ViewLayer.Normal.Z",
        "ViewLayer.Denoising Albedo.R",
        "ViewLayer.Denoising Albedo.G",
        "ViewLayer.Denoising Albedo.B",
        "ViewLayer.Depth.Z",
    ];
    write_foreign(&blender, w, h, &bnames);
    let f = read_exr(&blender).unwrap();
    let plane = |name: &str| f.channel(name).unwrap().to_vec();
    let check = |layer: &str, chans: &[&str]| {
        let im = f.layer(&[layer]).unwrap_or_else(|| panic!("{layer} not found in {:?}", f.channel_names()));
        assert_eq!(im.channels(), chans.len(), "{layer}");
        for (k, c) in chans.iter().enumerate() {
            let got: Vec<f32> = im.data().chunks_exact(chans.len()).map(|p| p[k]).collect();
            assert_eq!(got, plane(c), "{layer} channel {c}");
        }
    };
    check("color", &bnames[0..3]);
    check("normal", &bnames[4..7]);
    check("albedo", &bnames[7..10]);
    check("depth", &bnames[10..11]);
    assert!(f.layer(&["position"]).is_none());

    let image = dir.join("image.exr");
    write_foreign(&image, w, h, &["Image.R", "Image.G", "Image.B"]);
    let f2 = read_exr(&image).unwrap();
    assert_eq!(f2.layer(&["color"]).unwrap().channels(), 3);

    let mitsuba = dir.join("mitsuba.exr");
    let mnames = [
        "R",
        "G",
        "B",
        "A",
        "albedo.R",
        "albedo.G",
        "albedo.B",
        "nn.X",
        "nn.Y",
        "nn.Z",
        "position.X",
        "position.Y",
        "position.Z",
        "dd.Y",
    ];
    write_foreign(&mitsuba, w, h, &mnames);
    let f = read_exr(&mitsuba).unwrap();
    let plane = |name: &str| f.channel(name).unwrap().to_vec();
    for (layer, chans) in [
        ("color", &mnames[0..3]),
        ("albedo", &mnames[4..7]),
        ("normal", &mnames[7..10]),
        ("position", &mnames[10..13]),
        ("depth", &mnames[13..14]),
    ] {
        let im = f.layer(&[layer]).unwrap();
        for (k, c) in chans.iter().enumerate() {
            let got: Vec<f32> = im.data().chunks_exact(chans.len()).map(|p| p[k]).collect();
            assert_eq!(got, plane(c), "{layer} channel {c}");
        }
    }
    // u32 samples (object ids) become f32; a part of another size is skipped with a note.
    let ids = dir.join("ids.exr");
    {
        use exr::prelude::*;
        let id = AnyChannel::new("id.Y", FlatSamples::U32((0..(w * h) as u32).collect()));
        let red = AnyChannel::new("R", FlatSamples::F32(vec![0.5; w * h]));
        let small = AnyChannel::new("Y", FlatSamples::F32(vec![1.0; 4]));
        let a = Layer::new(
            (w, h),
            LayerAttributes::named("main"),
            Encoding::UNCOMPRESSED,
            AnyChannels::sort(SmallVec::from_vec(vec![id, red])),
        );
        let b = Layer::new(
            (2, 2),
            LayerAttributes::named("thumb"),
            Encoding::UNCOMPRESSED,
            AnyChannels::sort(SmallVec::from_vec(vec![small])),
        );
        Image::from_layers(
            ImageAttributes::new(IntegerBounds::from_dimensions((w, h))),
            SmallVec::from_vec(vec![a, b]),
        )
        .write()
        .to_file(&ids)
        .unwrap();
    }
    let f = read_exr(&ids).unwrap();
    assert_eq!(f.channel_names(), vec!["main.R".to_string(), "main.id.Y".to_string()]);
    assert_eq!(f.channel("main.id.Y").unwrap()[5], 5.0);
    assert_eq!(f.layer(&["id"]).unwrap().data()[w * h - 1], (w * h - 1) as f32);
    assert_eq!(f.warnings().len(), 1, "{:?}", f.warnings());
    // A plain RGB file has no depth: its bare R must not be taken for one.
    let rgb = dir.join("rgb.exr");
    write_foreign(&rgb, w, h, &["R", "G", "B"]);
    assert!(read_exr(&rgb).unwrap().layer(&["depth"]).is_none());
    std::fs::remove_dir_all(&dir).ok();
}

fn shared_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared")
}

#[test]
fn mitsuba_reference_has_the_documented_mean() {
    let path = shared_dir().join("reference/cornell_mitsuba_4096spp.exr");
    if !path.exists() {
        // CI must have the shared files: a missing one there is a failure, not a skip.
        assert!(std::env::var_os("CI").is_none(), "{} not found (CI is set)", path.display());
        println!("SKIP: {} not found (shared reference images absent)", path.display());
        return;
    }
    let f = read_exr(&path).unwrap();
    let color = f.require_layer(&["color"]).unwrap();
    assert_eq!((color.width(), color.height()), (512, 512));
    assert_eq!(color.count_non_finite(), 0);
    // The README's mean (0.241207 0.142099 0.060428) matches a naive f32 running sum
    // (0.2412066 0.1420990 0.0604279); the f64 mean is 0.2412089 0.1421203 0.0604281. The
    // tolerance covers that accumulation error (2.1e-5 in G) and nothing more: a wrong
    // channel order or an f16 truncation is off by far more.
    let mean = color.mean();
    for (m, want) in mean.iter().zip([0.241207, 0.142099, 0.060428]) {
        assert!((m - want).abs() < 5e-5, "mean {mean:?}");
    }
    for (m, want) in mean.iter().zip([0.2412089, 0.1421203, 0.0604281]) {
        assert!((m - want).abs() < 5e-7, "f64 mean {mean:?}");
    }
}

#[test]
fn errors_name_the_file_and_what_is_missing() {
    let dir = temp_dir("errors");
    let missing = dir.join("does-not-exist.exr");
    let e = read_exr(&missing).unwrap_err();
    assert!(e.to_string().contains("does-not-exist.exr"), "{e}");

    let garbage = dir.join("garbage.exr");
    std::fs::write(&garbage, b"this is not an exr").unwrap();
    let e = read_exr(&garbage).unwrap_err();
    assert!(matches!(e, IoError::Exr { .. } | IoError::Io { .. }), "{e:?}");
    assert!(e.to_string().contains("garbage.exr"), "{e}");

    let path = dir.join("rgb.exr");
    write_image(&path, &Image::filled(2, 2, 3, 0.5)).unwrap();
    let e = read_exr(&path).unwrap().require_layer(&["albedo"]).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("rgb.exr")
            && msg.contains("albedo")
            && (msg.contains("R, G, B") || msg.contains("B, G, R")),
        "{msg}"
    );

    let mut exr = ExrImage::new(2, 2);
    assert!(exr.insert("x", &["R", "G", "B"], &Image::new(3, 2, 3)).is_err());
    assert!(exr.insert("x", &["R", "G"], &Image::new(2, 2, 3)).is_err());
    assert!(write_exr(dir.join("empty.exr"), &ExrImage::new(0, 0)).is_err());
    assert!(write_image(dir.join("x.bmp"), &Image::new(2, 2, 3)).is_err());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn png_writes_nonfinite_as_zero_and_reports_the_count() {
    let dir = temp_dir("png");
    let mut im = Image::filled(4, 4, 3, 0.5);
    im.data_mut()[0] = f32::NAN;
    im.data_mut()[5] = f32::INFINITY;
    let path = dir.join("a.png");
    let report = write_png(&path, &im, &TonemapParams::default()).unwrap();
    assert_eq!(report.nonfinite, 2);
    let back = image::open(&path).unwrap().to_rgb8();
    assert_eq!(back.get_pixel(0, 0).0, [0, 188, 188]); // sRGB(0.5) = 0.7354 → 188
    assert_eq!(back.get_pixel(1, 0).0, [188, 188, 0]);
    assert_eq!(write_image(dir.join("b.png"), &Image::filled(2, 2, 1, 1.0)).unwrap(), 0);
    std::fs::remove_dir_all(&dir).ok();
}
