//! The tile cache against the in-memory textures (`TextureSet::load_within` with a share
//! smaller than the decoded pyramids, against `TextureSet::load`): every texel of every level,
//! random trilinear lookups in every wrap mode from two threads at once, the cache's peak
//! resident bytes within its share; and the tile file on resume: reused when complete,
//! rebuilt when truncated, corrupt or of changed sources.

use std::path::Path;

use voxlod_geom::{Material, Wrap};
use voxlod_texture::{TextureSet, MIN_CAPACITY, TILE_BYTES};

fn lcg(s: &mut u64) -> u64 {
    *s = s
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    *s >> 11
}

/// A `w × h` PNG of random texels (`alpha`: RGBA, else RGB) with smooth parts, so that the
/// mips differ from level to level.
fn png(path: &Path, w: u32, h: u32, seed: u64, alpha: bool) {
    let mut s = seed;
    let mut px = |x: u32, y: u32| -> [u8; 4] {
        let n = lcg(&mut s) as u8;
        [
            (x * 255 / w) as u8 ^ (n & 15),
            (y * 255 / h) as u8,
            n,
            if alpha { (n >> 1) | 64 } else { 255 },
        ]
    };
    if alpha {
        image::RgbaImage::from_fn(w, h, |x, y| image::Rgba(px(x, y)))
            .save(path)
            .unwrap();
    } else {
        image::RgbImage::from_fn(w, h, |x, y| {
            let p = px(x, y);
            image::Rgb([p[0], p[1], p[2]])
        })
        .save(path)
        .unwrap();
    }
}

/// Materials 1.. over three odd-sized textures, one of them under two wrap modes; material
/// 4 names a file that does not exist.
fn scene(dir: &Path) -> Vec<Material> {
    let files = [
        ("a.png", 517, 300, false),
        ("b.png", 1000, 77, true),
        ("c.png", 64, 200, false),
    ];
    for (i, (name, w, h, alpha)) in files.iter().enumerate() {
        png(&dir.join(name), *w, *h, i as u64 + 1, *alpha);
    }
    let m = |name: &str, file: &str, wrap: [Wrap; 2]| Material {
        name: name.into(),
        texture: Some(dir.join(file)),
        wrap,
        embedded: None,
    };
    vec![
        Material::default(),
        m("a", "a.png", [Wrap::Repeat, Wrap::Mirror]),
        m("b", "b.png", [Wrap::Clamp, Wrap::Repeat]),
        m("a-clamp", "a.png", [Wrap::Clamp; 2]),
        m("gone", "missing.png", [Wrap::Repeat; 2]),
        m("c", "c.png", [Wrap::Mirror, Wrap::Clamp]),
    ]
}

/// Every texel of every level and `n` random lookups of each material, bit for bit.
fn same_values(tiled: &TextureSet, whole: &TextureSet, n: usize, seed: u64) {
    for m in 0..6u32 {
        let (Some(a), Some(b)) = (tiled.get(m), whole.get(m)) else {
            assert!(tiled.get(m).is_none() && whole.get(m).is_none(), "{m}");
            continue;
        };
        assert!(a.is_tiled() && !b.is_tiled());
        assert_eq!((a.size(), a.levels()), (b.size(), b.levels()));
        for k in 0..a.levels() {
            let (w, h) = ((a.size().0 >> k).max(1), (a.size().1 >> k).max(1));
            for y in 0..h {
                for x in 0..w {
                    assert_eq!(
                        a.texel(k, x, y),
                        b.texel(k, x, y),
                        "m{m} level {k} ({x}, {y})"
                    );
                }
            }
        }
        let mut s = seed ^ m as u64;
        let mut f = |lo: f64, hi: f64| lo + (hi - lo) * (lcg(&mut s) as f64 / (1u64 << 53) as f64);
        for _ in 0..n {
            let (u, v) = (f(-2.0, 3.0), f(-2.0, 3.0));
            let lod = f(-1.0, a.levels() as f64 + 1.0) as f32;
            let (x, y) = (a.sample(u, v, lod), b.sample(u, v, lod));
            assert_eq!(
                x.map(f32::to_bits),
                y.map(f32::to_bits),
                "m{m} ({u}, {v}) lod {lod}"
            );
        }
    }
}

fn tiled(materials: &[Material], share: u64, file: &Path) -> TextureSet {
    let set = TextureSet::load_within(materials, share, file).unwrap();
    assert!(set.tiles().is_some(), "the textures exceed the share");
    set
}

#[test]
fn tiles_sample_as_the_whole_textures() {
    let d = tempfile::tempdir().unwrap();
    let materials = scene(d.path());
    let whole = TextureSet::load(&materials);
    // the decoded pyramids are about 2 MiB: a share of 16 tiles holds an eighth of them
    let share = 2 * MIN_CAPACITY;
    assert!(whole.bytes() as u64 >= 4 * share, "{}", whole.bytes());
    let file = d.path().join("textures.tiles");
    // the size the estimate gives from the headers is the size written
    let estimate = TextureSet::tile_file_bytes(&materials, share);
    let set = tiled(&materials, share, &file);
    assert_eq!(estimate, std::fs::metadata(&file).unwrap().len());
    assert_eq!(estimate, set.tiles().unwrap().file_bytes);
    assert_eq!(set.warnings.len(), 1, "{:?}", set.warnings);
    assert!(
        set.warnings[0].contains("missing.png"),
        "{:?}",
        set.warnings
    );
    assert_eq!(set.bytes(), whole.bytes());
    // two threads at once on the one cache
    std::thread::scope(|s| {
        for seed in [1, 2] {
            let (set, whole) = (&set, &whole);
            s.spawn(move || same_values(set, whole, 20_000, seed));
        }
    });
    let t = set.tiles().unwrap();
    let st = t.stats();
    assert!(st.peak_resident <= share && st.peak_resident > 0, "{st:?}");
    assert_eq!(st.capacity, share);
    // the texels were read many times over (evicted and read again)
    assert!(
        st.tile_reads * TILE_BYTES > 2 * whole.bytes() as u64,
        "{st:?}"
    );
    assert!(!t.reused && t.error().is_none());
    // a share that holds them all and the decoding of the largest (a.png, 517×300: its
    // texels and their RGBA8 copy) keeps them whole, as `load` does; one without room for the
    // decoding does not
    let decoding = 2 * 517 * 300 * 4;
    let big = TextureSet::load_within(&materials, whole.bytes() as u64 + decoding, &file).unwrap();
    assert!(big.tiles().is_none() && !big.get(1).unwrap().is_tiled());
    assert_eq!(
        TextureSet::tile_file_bytes(&materials, whole.bytes() as u64 + decoding),
        0
    );
    let near = TextureSet::load_within(&materials, whole.bytes() as u64, &file).unwrap();
    assert!(near.tiles().is_some());
}

#[test]
fn tile_file_is_reused_only_when_complete_and_current() {
    let d = tempfile::tempdir().unwrap();
    let materials = scene(d.path());
    let whole = TextureSet::load(&materials);
    let file = d.path().join("textures.tiles");
    let share = MIN_CAPACITY;
    drop(tiled(&materials, share, &file));
    let len = std::fs::metadata(&file).unwrap().len();
    assert!(!d.path().join("textures.tiles.part").exists());
    // complete: reused, the same values
    let set = tiled(&materials, share, &file);
    assert!(set.tiles().unwrap().reused);
    same_values(&set, &whole, 2000, 3);
    drop(set);
    // truncated (a build killed while renaming cannot leave this, a full disk or a copy can)
    let f = std::fs::OpenOptions::new().write(true).open(&file).unwrap();
    f.set_len(len - 5000).unwrap();
    drop(f);
    let set = tiled(&materials, share, &file);
    assert!(!set.tiles().unwrap().reused);
    assert_eq!(std::fs::metadata(&file).unwrap().len(), len);
    same_values(&set, &whole, 2000, 4);
    drop(set);
    // one texel byte flipped inside the tiles: the CRC fails, rebuilt
    let mut bytes = std::fs::read(&file).unwrap();
    bytes[3 * TILE_BYTES as usize + 77] ^= 0x40;
    std::fs::write(&file, &bytes).unwrap();
    let set = tiled(&materials, share, &file);
    assert!(!set.tiles().unwrap().reused);
    same_values(&set, &whole, 2000, 5);
    drop(set);
    // garbage of the right length
    std::fs::write(&file, vec![7u8; len as usize]).unwrap();
    let set = tiled(&materials, share, &file);
    assert!(!set.tiles().unwrap().reused);
    same_values(&set, &whole, 500, 6);
    drop(set);
    // a texture changed since (same size, other texels): rebuilt, the new texels
    std::thread::sleep(std::time::Duration::from_millis(20));
    png(&d.path().join("b.png"), 1000, 77, 99, true);
    let whole = TextureSet::load(&materials);
    let set = tiled(&materials, share, &file);
    assert!(!set.tiles().unwrap().reused);
    same_values(&set, &whole, 2000, 7);
}

#[test]
fn unwritable_tile_file_is_an_error_naming_it() {
    let d = tempfile::tempdir().unwrap();
    let materials = scene(d.path());
    let file = d.path().join("no such folder").join("textures.tiles");
    let e = TextureSet::load_within(&materials, MIN_CAPACITY, &file).unwrap_err();
    assert!(e.contains("no such folder/textures.tiles"), "{e}");
}

/// The memory budget: a texture whose decoded image alone exceeds the share is
/// decoded row by row when it is a PNG (here 4096² RGB: 64 MiB of RGBA8, 128 MiB with the
/// whole-image path's copy, under a 16 MiB share) with the texels of the whole decode; the same
/// image as JPEG cannot be decoded by rows and is refused with a warning that says how much
/// it takes and what to do, instead of going past the budget; a PNG cut short inside its image
/// data is a warning and leaves nothing of itself in the tile file (the others read right).
#[test]
fn textures_bigger_than_the_share_are_decoded_by_rows_or_refused() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let n = 4096u32;
    // smooth with a little noise: a small file that decodes big
    let mut s = 5u64;
    let img = image::RgbImage::from_fn(n, n, |x, y| {
        let r = lcg(&mut s) as u8 & 3;
        image::Rgb([(x / 16) as u8 ^ r, (y / 16) as u8, ((x + y) / 32) as u8])
    });
    img.save(dir.join("big.png")).unwrap();
    img.save(dir.join("big.jpg")).unwrap();
    let mut materials = scene(dir);
    let m = |name: &str, file: &str| Material {
        name: name.into(),
        texture: Some(dir.join(file)),
        wrap: [Wrap::Repeat; 2],
        embedded: None,
    };
    // a.png cut inside its image data
    let a = std::fs::read(dir.join("a.png")).unwrap();
    std::fs::write(dir.join("cut.png"), &a[..a.len() * 2 / 3]).unwrap();
    materials.push(m("big", "big.png")); // 6
    materials.push(m("big-jpeg", "big.jpg")); // 7
    materials.push(m("cut", "cut.png")); // 8
    let share = 16u64 << 20;
    let file = dir.join("textures.tiles");
    let set = tiled(&materials, share, &file);
    let warned = |what: &str| set.warnings.iter().filter(|w| w.contains(what)).count();
    assert_eq!(set.warnings.len(), 3, "{:?}", set.warnings);
    assert_eq!(warned("missing.png"), 1, "{:?}", set.warnings);
    assert_eq!(warned("cut.png"), 1, "{:?}", set.warnings);
    let jpeg = set.warnings.iter().find(|w| w.contains("big.jpg")).unwrap();
    assert!(
        jpeg.contains("128.0 MiB") && jpeg.contains("16.0 MiB") && jpeg.contains("--memory"),
        "{jpeg}"
    );
    assert!(set.get(6).is_some_and(|t| t.is_tiled()) && set.get(7).is_none());
    assert!(set.get(8).is_none());
    // the others read as the whole textures (the cut PNG left nothing behind)
    let whole = TextureSet::load(&materials[..6]);
    same_values(&set, &whole, 5000, 11);
    // the big PNG: its texels as image decodes them, at level 0 and in every mip
    let big = set.get(6).unwrap();
    let want = TextureSet::load(&materials[..7]);
    let want = want.get(6).unwrap();
    assert_eq!((big.size(), big.levels()), (want.size(), want.levels()));
    let mut r = 9u64;
    for _ in 0..200_000 {
        let (x, y) = (lcg(&mut r) as u32 % n, lcg(&mut r) as u32 % n);
        assert_eq!(big.texel(0, x, y), want.texel(0, x, y), "({x}, {y})");
    }
    for k in 4..big.levels() {
        let (w, h) = ((n >> k).max(1), (n >> k).max(1));
        for y in 0..h {
            for x in 0..w {
                assert_eq!(
                    big.texel(k, x, y),
                    want.texel(k, x, y),
                    "level {k} ({x}, {y})"
                );
            }
        }
    }
    assert!(set.tiles().unwrap().stats().peak_resident <= share);
}
