//! A little-endian baseline TIFF of one 8-bit band with the GeoTIFF 1.1 tags (OGC 19-008r4)
//! for a geographic WGS84 raster: all a map needs, and no more. Read back by GDAL in CI's
//! geo test (`tests/e2e_geo.rs`).

use super::GeoRaster;
use crate::gridmap::UNKNOWN;
use std::io::Write as _;

/// TIFF field types.
const SHORT: u16 = 3;
const LONG: u16 = 4;
const ASCII: u16 = 2;
const DOUBLE: u16 = 12;

/// A directory entry's values, written in place when they fit in four bytes.
enum Values {
    Short(Vec<u16>),
    Long(Vec<u32>),
    Ascii(String),
    Double(Vec<f64>),
}

impl Values {
    fn kind_and_count(&self) -> (u16, u32) {
        let (kind, n) = match self {
            Values::Short(v) => (SHORT, v.len()),
            Values::Long(v) => (LONG, v.len()),
            Values::Ascii(s) => (ASCII, s.len() + 1),
            Values::Double(v) => (DOUBLE, v.len()),
        };
        (kind, n as u32)
    }

    fn bytes(&self) -> Vec<u8> {
        match self {
            Values::Short(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Values::Long(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Values::Ascii(s) => s.bytes().chain([0]).collect(),
            Values::Double(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }
}

/// Rows a strip holds: strips of about 64 KiB, as GDAL's own writer makes them.
fn rows_per_strip(width: usize) -> usize {
    (65_536 / width.max(1)).max(1)
}

/// The raster as a GeoTIFF in EPSG:4326 (see [`GeoRaster::to_geotiff`]).
pub(crate) fn geotiff_epsg4326(raster: &GeoRaster) -> Vec<u8> {
    let rows = rows_per_strip(raster.width);
    let strips: Vec<Vec<u8>> = raster
        .pixels
        .chunks(rows * raster.width)
        .map(|strip| {
            let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(6));
            z.write_all(strip).expect("writes to memory");
            z.finish().expect("writes to memory")
        })
        .collect();
    // GeoKeyDirectory: version 1.1.0, then (key, location 0 = the value itself, 1, value):
    // a geographic model, pixel-is-area, EPSG:4326, angles in degrees.
    let geokeys = vec![
        1, 1, 0, 4, //
        1024, 0, 1, 2, // GTModelTypeGeoKey: ModelTypeGeographic
        1025, 0, 1, 1, // GTRasterTypeGeoKey: RasterPixelIsArea
        2048, 0, 1, 4326, // GeodeticCRSGeoKey: WGS 84
        2054, 0, 1, 9102, // GeogAngularUnitsGeoKey: degree
    ];
    let (w, h) = (raster.width as u32, raster.height as u32);
    // Strip offsets are filled in below, once the layout is known.
    let mut entries: Vec<(u16, Values)> = vec![
        (256, Values::Long(vec![w])),           // ImageWidth
        (257, Values::Long(vec![h])),           // ImageLength
        (258, Values::Short(vec![8])),          // BitsPerSample
        (259, Values::Short(vec![8])),          // Compression: Deflate (zlib)
        (262, Values::Short(vec![1])),          // PhotometricInterpretation: BlackIsZero
        (273, Values::Long(vec![])),            // StripOffsets
        (277, Values::Short(vec![1])),          // SamplesPerPixel
        (278, Values::Long(vec![rows as u32])), // RowsPerStrip
        (
            279,
            Values::Long(strips.iter().map(|s| s.len() as u32).collect()),
        ), // StripByteCounts
        (284, Values::Short(vec![1])),          // PlanarConfiguration: chunky
        (339, Values::Short(vec![1])),          // SampleFormat: unsigned
        (
            33550,
            Values::Double(vec![raster.pixel_deg[0], raster.pixel_deg[1], 0.0]),
        ), // ModelPixelScale
        (
            33922,
            Values::Double(vec![0.0, 0.0, 0.0, raster.west_deg, raster.north_deg, 0.0]),
        ), // ModelTiepoint: pixel (0, 0)'s corner
        (34735, Values::Short(geokeys)),        // GeoKeyDirectory
        (42113, Values::Ascii(UNKNOWN.to_string())), // GDAL_NODATA
    ];
    let ifd_len = 2 + entries.len() * 12 + 4;
    let extra_len = |entries: &[(u16, Values)]| -> usize {
        entries
            .iter()
            .map(|(_, v)| v.bytes().len())
            .filter(|&n| n > 4)
            .map(|n| n + (n & 1))
            .sum()
    };
    let strip_ids = 273;
    let data_start = {
        // The offsets' own array, not yet filled, is as long as the counts'.
        let offsets = &mut entries.iter_mut().find(|(t, _)| *t == strip_ids).unwrap().1;
        *offsets = Values::Long(vec![0; strips.len()]);
        8 + ifd_len + extra_len(&entries)
    };
    let mut at = data_start;
    let offsets: Vec<u32> = strips
        .iter()
        .map(|s| {
            let o = at as u32;
            at += s.len();
            o
        })
        .collect();
    entries.iter_mut().find(|(t, _)| *t == strip_ids).unwrap().1 = Values::Long(offsets);

    let mut out = Vec::with_capacity(at);
    out.extend_from_slice(b"II");
    out.extend_from_slice(&42u16.to_le_bytes());
    out.extend_from_slice(&8u32.to_le_bytes());
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    let mut extra = Vec::new();
    for (tag, values) in &entries {
        let (kind, count) = values.kind_and_count();
        out.extend_from_slice(&tag.to_le_bytes());
        out.extend_from_slice(&kind.to_le_bytes());
        out.extend_from_slice(&count.to_le_bytes());
        let bytes = values.bytes();
        if bytes.len() <= 4 {
            let mut inline = [0u8; 4];
            inline[..bytes.len()].copy_from_slice(&bytes);
            out.extend_from_slice(&inline);
        } else {
            let offset = 8 + ifd_len + extra.len();
            out.extend_from_slice(&(offset as u32).to_le_bytes());
            extra.extend_from_slice(&bytes);
            if bytes.len() % 2 == 1 {
                extra.push(0); // values start on a word boundary
            }
        }
    }
    out.extend_from_slice(&0u32.to_le_bytes()); // no next directory
    out.extend_from_slice(&extra);
    debug_assert_eq!(out.len(), data_start);
    for strip in &strips {
        out.extend_from_slice(strip);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read as _;

    fn u16_at(b: &[u8], at: usize) -> u16 {
        u16::from_le_bytes([b[at], b[at + 1]])
    }
    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    #[test]
    fn the_strips_hold_the_pixels_and_the_tags_are_sorted() {
        let (width, height) = (700, 300);
        let raster = GeoRaster {
            width,
            height,
            west_deg: 9.7,
            north_deg: 52.4,
            pixel_deg: [1.5e-6, 0.9e-6],
            pixels: (0..width * height).map(|i| (i % 251) as u8).collect(),
        };
        let tif = geotiff_epsg4326(&raster);
        assert_eq!(&tif[..4], b"II\x2a\x00");
        let ifd = u32_at(&tif, 4) as usize;
        let n = u16_at(&tif, ifd) as usize;
        let entry = |tag: u16| {
            (0..n)
                .map(|k| ifd + 2 + 12 * k)
                .find(|&e| u16_at(&tif, e) == tag)
                .unwrap_or_else(|| panic!("tag {tag}"))
        };
        let tags: Vec<u16> = (0..n).map(|k| u16_at(&tif, ifd + 2 + 12 * k)).collect();
        assert!(tags.windows(2).all(|p| p[0] < p[1]), "{tags:?}");
        let count = u32_at(&tif, entry(273) + 4) as usize;
        let offsets_at = u32_at(&tif, entry(273) + 8) as usize;
        let counts_at = u32_at(&tif, entry(279) + 8) as usize;
        let mut pixels = Vec::new();
        for k in 0..count {
            let (o, c) = (
                u32_at(&tif, offsets_at + 4 * k) as usize,
                u32_at(&tif, counts_at + 4 * k) as usize,
            );
            flate2::read::ZlibDecoder::new(&tif[o..o + c])
                .read_to_end(&mut pixels)
                .unwrap();
        }
        assert_eq!(pixels, raster.pixels);
        let tie_at = u32_at(&tif, entry(33922) + 8) as usize;
        let west = f64::from_le_bytes(tif[tie_at + 24..tie_at + 32].try_into().unwrap());
        assert_eq!(west, 9.7);
    }
}
