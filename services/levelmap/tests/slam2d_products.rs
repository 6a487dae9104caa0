//! `levelmap slam2d` writes the map products through graphio's encoders: the occupancy grid
//! as PNG and as PGM + YAML, every scan's pose as TUM text.

use std::process::Command;

#[test]
fn slam2d_writes_grid_images_and_trajectory() {
    let log = testdata::shared_data("radish_2d_corrected_logs/aces-corrected.log.gz");
    let dir = std::env::temp_dir().join(format!("levelmap-test-{}-products", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let (png, pgm, tum) = (
        dir.join("map.png"),
        dir.join("map.pgm"),
        dir.join("run.tum"),
    );
    let out = Command::new(env!("CARGO_BIN_EXE_levelmap"))
        .args(["slam2d", log.to_str().unwrap(), "--json", "--png"])
        .arg(&png)
        .arg("--pgm")
        .arg(&pgm)
        .arg("--trajectory")
        .arg(&tum)
        .output()
        .expect("run levelmap");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // PNG: signature, then IHDR with width and height (big-endian), 8-bit greyscale.
    let png = std::fs::read(&png).expect("png");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    assert_eq!(&png[12..16], b"IHDR");
    let be = |b: &[u8]| u32::from_be_bytes(b.try_into().unwrap()) as usize;
    let (w, h) = (be(&png[16..20]), be(&png[20..24]));
    assert_eq!(
        (png[24], png[25]),
        (8, 0),
        "bit depth 8, colour type greyscale"
    );

    // PGM of the same size, its YAML beside it naming it.
    let pgm = std::fs::read(&pgm).expect("pgm");
    let header = format!("P5\n# CREATOR: map_saver.cpp 0.100 m/pix\n{w} {h}\n255\n");
    assert!(pgm.starts_with(header.as_bytes()), "{:?}", &pgm[..40]);
    assert_eq!(pgm.len(), header.len() + w * h);
    assert!(
        pgm[header.len()..]
            .iter()
            .all(|v| [0, 205, 254].contains(v))
    );
    let yaml = std::fs::read_to_string(dir.join("map.yaml")).expect("yaml");
    let field = |name: &str| {
        yaml.lines()
            .find_map(|l| l.strip_prefix(&format!("{name}: ")))
            .unwrap_or_else(|| panic!("{name} missing: {yaml}"))
            .to_string()
    };
    assert_eq!(field("image"), "map.pgm");
    assert_eq!(field("resolution").parse::<f64>().unwrap(), 0.1);
    let origin: Vec<f64> = field("origin")
        .trim_matches(['[', ']'])
        .split(", ")
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(origin.len(), 3);
    assert_eq!(origin[2], 0.0);
    assert_eq!(field("negate"), "0");
    assert_eq!(field("occupied_thresh"), "0.65");
    assert_eq!(field("free_thresh"), "0.196");

    // TUM: the header, then one line of 8 numbers per scan.
    let tum = std::fs::read_to_string(&tum).expect("tum");
    let lines: Vec<&str> = tum.lines().collect();
    assert!(lines[0].starts_with('#'));
    assert_eq!(lines.len(), 1 + 440);
    assert!(lines[1..].iter().all(|l| l.split(' ').count() == 8));
    std::fs::remove_dir_all(&dir).ok();
}
