//! Fuzzing of the EXR reader: mutations of valid files (every compression the `exr` crate
//! writes, scan lines and tiles, f16/f32/u32 samples, multi-part) must end in `Ok` with
//! consistent channel planes or in an error: never a panic, never a case over the time
//! limit, never growth past the child's address-space limit (see `fuzz_support`, shared
//! with the scene loaders' fuzz tests).

#[path = "../../scene/tests/fuzz_support/mod.rs"]
mod fuzz_support;

use std::io::Cursor;

use exr::prelude as x;
use exr::prelude::WritableImage;
use filtrace_io::read_exr;
use fuzz_support::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};

const W: usize = 13;
const H: usize = 7;

fn samples_f16(k: usize) -> x::FlatSamples {
    x::FlatSamples::F16((0..W * H).map(|i| x::f16::from_f32((i * (k + 1)) as f32 * 0.01)).collect())
}

fn samples_f32(k: usize) -> x::FlatSamples {
    x::FlatSamples::F32((0..W * H).map(|i| (i + k) as f32 * 0.1).collect())
}

fn layer(
    name: &str,
    compression: x::Compression,
    blocks: x::Blocks,
    f16: bool,
) -> x::Layer<x::AnyChannels<x::FlatSamples>> {
    let s = |k| if f16 { samples_f16(k) } else { samples_f32(k) };
    let list = x::SmallVec::from_vec(vec![
        x::AnyChannel::new("B", s(0)),
        x::AnyChannel::new("G", s(1)),
        x::AnyChannel::new("R", s(2)),
        x::AnyChannel::new("id", x::FlatSamples::U32((0..(W * H) as u32).collect())),
    ]);
    let encoding = x::Encoding { compression, blocks, line_order: x::LineOrder::Increasing };
    x::Layer::new((W, H), x::LayerAttributes::named(name), encoding, x::AnyChannels::sort(list))
}

fn encode(layers: Vec<x::Layer<x::AnyChannels<x::FlatSamples>>>) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    x::Image::from_layers(x::ImageAttributes::new(x::IntegerBounds::from_dimensions((W, H))), layers)
        .write()
        .to_buffered(&mut out)
        .expect("encode a seed EXR");
    out.into_inner()
}

/// One seed per compression (f16 where the method is lossy for f32), tiled and scan-line,
/// and a two-part file.
fn seeds() -> Vec<Vec<u8>> {
    use x::Compression::*;
    let lines = x::Blocks::ScanLines;
    let tiles = x::Blocks::Tiles(x::Vec2(8, 4));
    vec![
        encode(vec![layer("", Uncompressed, lines, false)]),
        encode(vec![layer("", RLE, tiles, false)]),
        encode(vec![layer("", ZIP1, lines, true)]),
        encode(vec![layer("", ZIP16, tiles, false)]),
        encode(vec![layer("", PIZ, lines, true)]),
        encode(vec![layer("", PXR24, lines, true)]),
        encode(vec![layer("", B44, tiles, true)]),
        encode(vec![layer("", B44A, lines, true)]),
        encode(vec![layer("beauty", ZIP16, lines, false), layer("albedo", RLE, tiles, true)]),
    ]
}

/// Reads `bytes` as a file; true when it read (and then its planes are consistent).
fn check(dir: &std::path::Path, bytes: &[u8]) -> bool {
    let path = dir.join("fuzz.exr");
    std::fs::write(&path, bytes).expect("write the fuzz case");
    let Ok(img) = read_exr(&path) else { return false };
    {
        let n = img.width() * img.height();
        assert!(img.channels().iter().all(|c| c.data.len() == n), "a plane of the wrong length");
        // The layer lookups used by the CLI on what was read.
        let _ = img.layer(&["color"]);
        let _ = img.layer_prefixes();
    }
    true
}

fn fuzz_exr(cases: u32) {
    let dir = temp_dir("exr");
    let seeds = seeds();
    for (i, s) in seeds.iter().enumerate() {
        std::fs::write(dir.join("seed.exr"), s).unwrap();
        let img = read_exr(dir.join("seed.exr")).unwrap_or_else(|e| panic!("seed {i}: {e}"));
        assert!(img.channels().len() >= 4, "seed {i}: {:?}", img.channel_names());
    }
    let dog = Watchdog::new(CASE_LIMIT);
    let config = Config { cases, failure_persistence: None, ..Config::default() };
    let mut runner = TestRunner::new_with_rng(config, TestRng::from_seed(RngAlgorithm::ChaCha, &[17; 32]));
    let loaded = std::cell::Cell::new(0u32);
    let result = runner.run(&(0..seeds.len(), mutations(3)), |(i, muts)| {
        dog.case(format!("exr seed {i}, mutations {muts:?}"));
        loaded.set(loaded.get() + check(&dir, &apply(&seeds[i], &muts)) as u32);
        Ok(())
    });
    if let Err(e) = result {
        panic!("exr: {e}");
    }
    let ok = loaded.get();
    println!("exr: {cases} cases, {ok} read, the others ended in an error");
    // Mutations that all die at the first check would test nothing deeper.
    assert!(ok * 20 >= cases, "exr: only {ok} of {cases} mutated files read");
}

#[test]
fn exr_fuzz() {
    if limited_child("exr_fuzz", false) {
        fuzz_exr(FAST_CASES);
    }
}

#[test]
#[ignore = "slow: fuzz"]
fn exr_fuzz_slow() {
    if limited_child("exr_fuzz_slow", true) {
        fuzz_exr(SLOW_CASES);
    }
}

/// Found by `exr_fuzz`: a corrupt B44 tile made the decoder overflow on one of exr's worker
/// threads, and rayon aborted the whole process. Now an error naming the file.
#[test]
fn corrupt_b44_tile_is_an_error_not_an_abort() {
    let dir = temp_dir("exr-b44");
    let seed = &seeds()[6]; // B44, tiled
    let bytes = apply(seed, &[Mutation::Word { pos: 1754591644524502201, value: 2 }]);
    let path = dir.join("b44.exr");
    std::fs::write(&path, bytes).unwrap();
    let e = read_exr(&path).expect_err("a corrupt B44 tile is an error").to_string();
    assert!(e.contains("b44.exr"), "{e}");
}

/// Found by `exr_fuzz_slow` under the memory limit: a data window widened to 16 M pixels in a
/// 1 kB B44A file made the decoder allocate 1.2 GB per block (and a wider one aborts on an
/// allocation that cannot succeed). The claimed size is now checked against the file's.
#[test]
fn data_window_beyond_what_the_file_can_hold_is_an_error() {
    let dir = temp_dir("exr-window");
    let mut bytes = seeds()[7].clone(); // B44A, scan lines
    let key = b"dataWindow\0box2i\0";
    let at = bytes.windows(key.len()).position(|w| w == key).expect("a dataWindow attribute") + key.len();
    // Size (4 bytes), then xMin, yMin, xMax, yMax.
    bytes[at + 12..at + 16].copy_from_slice(&16_000_000i32.to_le_bytes());
    let path = dir.join("wide.exr");
    std::fs::write(&path, &bytes).unwrap();
    let e = read_exr(&path).expect_err("a corrupt size is an error").to_string();
    assert!(e.contains("wide.exr") && e.contains("claims"), "{e}");
}
