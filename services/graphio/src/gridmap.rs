//! The occupancy grid as images: PNG (for the dashboard and the command line) and PGM + YAML
//! exactly as ROS map_server's `map_saver` writes them, so `map_server` (ROS 1) and
//! `nav2_map_server` load levelmap maps unchanged.
//!
//! Both images are trinary by default, with map_saver's grey levels: free 254, occupied 0,
//! unknown 205 (the tri-state of [`OccupancyGrid::state`]). In map_server's `scale` mode
//! ([`MapMode::Scale`]) the PNG carries the evidence instead: each known cell's grey is
//! 255·(1 − p), unknown is transparent, and map_server loads the cells between the two
//! thresholds as 1–99 ([`map_server_value`]). Rows go from the top of the map (largest y,
//! north) down, as image rows do; the grid's row 0 is its bottom row.

use crate::EncodeError;
use slam::grid::{CellState, OccupancyGrid};
use std::fmt::Write as _;

/// Grey level of a free cell.
pub const FREE: u8 = 254;
/// Grey level of an occupied cell.
pub const OCCUPIED: u8 = 0;
/// Grey level of an unknown cell: map_server reads (255 − 205)/255 = 0.196, not below
/// `free_thresh`, not above `occupied_thresh`.
pub const UNKNOWN: u8 = 205;

/// `occupied_thresh` and `free_thresh` of the YAML, map_saver's constants: they classify
/// the three grey levels above back into the same three states.
pub const OCCUPIED_THRESH: f64 = 0.65;
/// `free_thresh` of the YAML (see [`OCCUPIED_THRESH`]).
pub const FREE_THRESH: f64 = 0.196;

/// How map_server reads a map image (its YAML's `mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MapMode {
    /// Free, occupied or unknown (map_saver's default).
    #[default]
    Trinary,
    /// The evidence: between the thresholds a cell is 1–99, unknown from the alpha channel.
    Scale,
}

impl std::str::FromStr for MapMode {
    type Err = String;

    /// `trinary` or `scale`, as the YAML's `mode` names them.
    fn from_str(s: &str) -> Result<MapMode, String> {
        match s {
            "trinary" => Ok(MapMode::Trinary),
            "scale" => Ok(MapMode::Scale),
            other => Err(format!("mode={other:?}: want trinary or scale")),
        }
    }
}

/// The value map_server (ROS 1 and Nav2) gives a cell of `grid` holding `occupancy` (−1 or
/// 0–100) when it loads this module's image in `mode`: −1 unknown, 0 free, 100 occupied and,
/// in `Scale` mode, (p − free)/(occupied − free) × 100 in between, rounded. The ROS 2 map
/// publication uses it, so it carries what a map_server would.
pub fn map_server_value(grid: &OccupancyGrid, occupancy: i8, mode: MapMode) -> i8 {
    match (grid.classify(occupancy), mode) {
        (CellState::Free, _) => 0,
        (CellState::Occupied, _) => 100,
        (CellState::Unknown, MapMode::Trinary) => -1,
        (CellState::Unknown, MapMode::Scale) if occupancy < 0 => -1,
        (CellState::Unknown, MapMode::Scale) => {
            let (free, occupied) = (
                f64::from(grid.free_percent),
                f64::from(grid.occupied_percent),
            );
            ((f64::from(occupancy) - free) / (occupied - free) * 100.0).round() as i8
        }
    }
}

/// The grid as map_server's `scale` mode reads it: a grey-and-alpha PNG, each known cell
/// 255·(1 − p) and opaque, unknown transparent, north up. Its YAML
/// ([`to_map_yaml_with`] in [`MapMode::Scale`]) carries the grid's own thresholds.
pub fn to_png_scale(grid: &OccupancyGrid) -> Result<Vec<u8>, EncodeError> {
    to_png_scale_with(grid, PngSpeed::Small)
}

/// [`to_png_scale`] at the given compression.
pub fn to_png_scale_with(grid: &OccupancyGrid, speed: PngSpeed) -> Result<Vec<u8>, EncodeError> {
    check_grid(grid)?;
    let mut pixels = Vec::with_capacity(2 * grid.cells.len());
    for row in grid.cells.chunks_exact(grid.width).rev() {
        pixels.extend(row.iter().flat_map(|&c| {
            if c < 0 {
                [UNKNOWN, 0]
            } else {
                [(255.0 * (1.0 - f64::from(c) / 100.0)).round() as u8, 255]
            }
        }));
    }
    encode_png(grid, &pixels, png::ColorType::GrayscaleAlpha, speed)
}

/// Checks that `grid` has cells, that they match its size, and that it lies somewhere.
pub(crate) fn check_grid(grid: &OccupancyGrid) -> Result<(), EncodeError> {
    let (w, h) = (grid.width, grid.height);
    let placed = grid.resolution_m.is_finite()
        && grid.resolution_m > 0.0
        && grid.origin_m.iter().all(|v| v.is_finite());
    if w == 0 || h == 0 || w.checked_mul(h) != Some(grid.cells.len()) || !placed {
        return Err(EncodeError::BadGrid {
            width: w,
            height: h,
            cells: grid.cells.len(),
        });
    }
    Ok(())
}

/// The grid's pixels, one grey byte a cell, top row (largest y) first.
pub fn trinary_pixels(grid: &OccupancyGrid) -> Result<Vec<u8>, EncodeError> {
    check_grid(grid)?;
    let mut pixels = Vec::with_capacity(grid.cells.len());
    for row in grid.cells.chunks_exact(grid.width).rev() {
        pixels.extend(row.iter().map(|&c| match grid.classify(c) {
            CellState::Free => FREE,
            CellState::Occupied => OCCUPIED,
            CellState::Unknown => UNKNOWN,
        }));
    }
    Ok(pixels)
}

/// How hard a PNG is compressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PngSpeed {
    /// The smallest file for the time (png's balanced deflate): whole maps.
    Small,
    /// About 20× faster and twice the size (a 400 × 400 trinary window: 0.12 ms instead of
    /// 2.6 ms): pictures made many times a second, such as windows around robots.
    Fast,
}

/// The grid as an 8-bit greyscale PNG, north up.
pub fn to_png(grid: &OccupancyGrid) -> Result<Vec<u8>, EncodeError> {
    to_png_with(grid, PngSpeed::Small)
}

/// [`to_png`] at the given compression.
pub fn to_png_with(grid: &OccupancyGrid, speed: PngSpeed) -> Result<Vec<u8>, EncodeError> {
    let pixels = trinary_pixels(grid)?;
    encode_png(grid, &pixels, png::ColorType::Grayscale, speed)
}

/// `pixels` (top row first) as an 8-bit PNG of the grid's size.
fn encode_png(
    grid: &OccupancyGrid,
    pixels: &[u8],
    color: png::ColorType,
    speed: PngSpeed,
) -> Result<Vec<u8>, EncodeError> {
    let too_large = || EncodeError::GridTooLarge {
        width: grid.width,
        height: grid.height,
    };
    let w = u32::try_from(grid.width).map_err(|_| too_large())?;
    let h = u32::try_from(grid.height).map_err(|_| too_large())?;
    let mut out = Vec::with_capacity(pixels.len() / 8 + 64);
    let mut encoder = png::Encoder::new(&mut out, w, h);
    encoder.set_color(color);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(match speed {
        PngSpeed::Small => png::Compression::Balanced,
        PngSpeed::Fast => png::Compression::Fast,
    });
    // Maps are long runs of a few values: the default filter and compression already make
    // them small.
    encoder
        .write_header()
        .and_then(|mut writer| writer.write_image_data(pixels))
        .map_err(|e| EncodeError::Png(e.to_string()))?;
    Ok(out)
}

/// The grid as binary PGM (P5), byte for byte as map_saver writes it: its comment line
/// with the resolution, then width, height, 255, and the pixels top row first.
pub fn to_pgm(grid: &OccupancyGrid) -> Result<Vec<u8>, EncodeError> {
    let pixels = trinary_pixels(grid)?;
    let header = format!(
        "P5\n# CREATOR: map_saver.cpp {:.3} m/pix\n{} {}\n255\n",
        grid.resolution_m, grid.width, grid.height
    );
    let mut out = Vec::with_capacity(header.len() + pixels.len());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(&pixels);
    Ok(out)
}

/// The map_server YAML of the PGM named `image` (relative to the YAML file, as map_saver
/// writes it), with map_saver's fields and number format. The origin is the grid's
/// lower-left corner, with yaw 0 (the grid is axis-aligned with the map frame).
pub fn to_map_yaml(grid: &OccupancyGrid, image: &str) -> String {
    to_map_yaml_with(grid, image, MapMode::Trinary)
}

/// [`to_map_yaml`] for an image in `mode`: in `Scale` mode with `mode: scale` and the grid's
/// own thresholds (so map_server's free, occupied and in-between are the grid's).
pub fn to_map_yaml_with(grid: &OccupancyGrid, image: &str, mode: MapMode) -> String {
    let mut s = String::with_capacity(176);
    let _ = writeln!(s, "image: {}", yaml_scalar(image));
    let _ = writeln!(s, "resolution: {:.6}", grid.resolution_m);
    let _ = writeln!(
        s,
        "origin: [{:.6}, {:.6}, {:.6}]",
        grid.origin_m[0], grid.origin_m[1], 0.0
    );
    let _ = writeln!(s, "negate: 0");
    match mode {
        MapMode::Trinary => {
            let _ = writeln!(s, "occupied_thresh: {OCCUPIED_THRESH}");
            let _ = writeln!(s, "free_thresh: {FREE_THRESH}");
        }
        MapMode::Scale => {
            let _ = writeln!(
                s,
                "occupied_thresh: {}",
                f64::from(grid.occupied_percent) / 100.0
            );
            let _ = writeln!(s, "free_thresh: {}", f64::from(grid.free_percent) / 100.0);
            let _ = writeln!(s, "mode: scale");
        }
    }
    s.push('\n');
    s
}

/// `name` as a YAML plain scalar when that is safe (map_saver writes it bare), else
/// double-quoted, so a file name with `: ` or `#` cannot break the YAML.
fn yaml_scalar(name: &str) -> String {
    let plain = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_alphanumeric() || "._-/+~".contains(c))
        && !name.starts_with(['-', '~']);
    if plain {
        return name.to_string();
    }
    let mut q = String::with_capacity(name.len() + 2);
    q.push('"');
    for c in name.chars() {
        match c {
            '"' => q.push_str("\\\""),
            '\\' => q.push_str("\\\\"),
            c if c.is_control() => {
                let _ = write!(q, "\\u{:04x}", u32::from(c));
            }
            c => q.push(c),
        }
    }
    q.push('"');
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 3 wide, 2 high: bottom row free, unknown, occupied; top row never seen, 50 %, 10 %.
    fn small() -> OccupancyGrid {
        OccupancyGrid {
            resolution_m: 0.05,
            origin_m: [-1.5, -0.25],
            width: 3,
            height: 2,
            cells: vec![0, -1, 100, -1, 50, 10],
            occupied_percent: 65,
            free_percent: 35,
        }
    }

    #[test]
    fn pgm_is_map_saver_bytes_top_row_first() {
        let pgm = to_pgm(&small()).unwrap();
        let header = b"P5\n# CREATOR: map_saver.cpp 0.050 m/pix\n3 2\n255\n";
        assert_eq!(&pgm[..header.len()], header);
        assert_eq!(&pgm[header.len()..], &[205, 205, 254, 254, 205, 0]);
    }

    #[test]
    fn png_decodes_to_the_grid_north_up() {
        let png = to_png(&small()).unwrap();
        let mut reader = png::Decoder::new(std::io::Cursor::new(png))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (3, 2));
        assert_eq!(info.color_type, png::ColorType::Grayscale);
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        assert_eq!(&buf[..info.buffer_size()], &[205, 205, 254, 254, 205, 0]);
    }

    #[test]
    fn yaml_has_map_saver_fields() {
        let yaml = to_map_yaml(&small(), "site.pgm");
        assert_eq!(
            yaml,
            "image: site.pgm\nresolution: 0.050000\norigin: [-1.500000, -0.250000, 0.000000]\n\
             negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n\n"
        );
        assert!(to_map_yaml(&small(), "my map: v2.pgm").starts_with("image: \"my map: v2.pgm\"\n"));
        // The grey levels classify back as map_server does: p = (255 − v)/255.
        let p = |v: u8| f64::from(255 - v) / 255.0;
        assert!(p(OCCUPIED) > OCCUPIED_THRESH && p(FREE) < FREE_THRESH);
        assert!((FREE_THRESH..=OCCUPIED_THRESH).contains(&p(UNKNOWN)));
    }

    #[test]
    fn scale_mode_carries_the_evidence_as_map_server_reads_it() {
        let g = small();
        let png = to_png_scale(&g).unwrap();
        let mut reader = png::Decoder::new(std::io::Cursor::new(png))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::GrayscaleAlpha);
        // Top row: never seen (transparent), 50 %, 10 %; bottom: 0 %, never seen, 100 %.
        assert_eq!(
            &buf[..info.buffer_size()],
            &[205, 0, 128, 255, 230, 255, 255, 255, 205, 0, 0, 255]
        );
        // map_server's scale mode on those pixels: occ = 1 − grey/255 against the YAML's
        // thresholds, in between scaled; transparent is unknown.
        let yaml = to_map_yaml_with(&g, "m.png", MapMode::Scale);
        assert!(
            yaml.contains("occupied_thresh: 0.65\nfree_thresh: 0.35\nmode: scale\n"),
            "{yaml}"
        );
        let load = |grey: u8, alpha: u8| -> i8 {
            let occ = 1.0 - f64::from(grey) / 255.0;
            if alpha != 255 {
                -1
            } else if occ > 0.65 {
                100
            } else if occ < 0.35 {
                0
            } else {
                ((occ - 0.35) / 0.30 * 100.0).round() as i8
            }
        };
        for (&cell, px) in [-1i8, 50, 10, 0, -1, 100].iter().zip(buf.chunks(2)) {
            let ours = map_server_value(&g, cell, MapMode::Scale);
            assert!(
                (i16::from(ours) - i16::from(load(px[0], px[1]))).abs() <= 1,
                "{cell}: {ours}"
            );
        }
        assert_eq!(map_server_value(&g, 50, MapMode::Trinary), -1);
        assert_eq!(map_server_value(&g, 50, MapMode::Scale), 50);
    }

    #[test]
    fn malformed_grids_are_errors() {
        let mut g = small();
        g.cells.pop();
        assert!(matches!(
            to_png(&g),
            Err(EncodeError::BadGrid { cells: 5, .. })
        ));
        g.width = 0;
        g.cells.clear();
        assert!(matches!(to_pgm(&g), Err(EncodeError::BadGrid { .. })));
    }
}
