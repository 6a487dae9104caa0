//! SVG pictures of leveled scans, as the paper's Fig. 4: the leveled range scan (red) over
//! what a fixed horizontal 2D scanner at the sensor sees (black).

use leveling::{Leveled, PointClass, Scan3d, horizontal_cut};
use std::fmt::Write;

/// Half-width of the elevation band taken as the horizontal 2D cut.
const CUT_ELEVATION_RAD: f32 = 0.5 * std::f32::consts::PI / 180.0;

/// Fig. 4 for one scan: landmark points (pink), leveled beams (red), the fixed 2D cut (black),
/// a 10 m grid and the sensor at the origin. x forward points up the page.
pub fn fig4(raw: &Scan3d, leveled: &Leveled, title: &str) -> String {
    let cut = horizontal_cut(raw, CUT_ELEVATION_RAD);
    let beams: Vec<(f32, f32)> = leveled.scan.returns().collect();
    let landmarks: Vec<[f32; 2]> = leveled
        .cloud
        .columns
        .iter()
        .flat_map(|c| {
            let range = c.start as usize..(c.start + c.len) as usize;
            let classes = &leveled.classes[range.clone()];
            leveled.cloud.points[range]
                .iter()
                .zip(classes)
                .filter(|(_, k)| **k == PointClass::Landmark)
                .map(move |(p, _)| {
                    let [x, y, _] = p.to_xyz();
                    [x + c.origin_xy_m[0], y + c.origin_xy_m[1]]
                })
        })
        .collect();
    let polar = |&(phi, r): &(f32, f32)| [r * phi.cos(), r * phi.sin()];
    let beam_xy: Vec<[f32; 2]> = beams.iter().map(polar).collect();
    let cut_xy: Vec<[f32; 2]> = cut.iter().map(polar).collect();

    // Extent: the 98th percentile of beam and cut ranges, at least 10 m.
    let mut ranges: Vec<f32> = beams.iter().chain(&cut).map(|b| b.1).collect();
    ranges.sort_by(f32::total_cmp);
    let extent = ranges
        .get(ranges.len() * 98 / 100)
        .copied()
        .unwrap_or(10.0)
        .max(10.0)
        .ceil()
        + 2.0;
    let size = 900.0;
    let scale = size / (2.0 * extent);
    // Page coordinates: x forward → up, y left → left.
    let page = |p: &[f32; 2]| (size / 2.0 - p[1] * scale, size / 2.0 - p[0] * scale);

    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{size}" height="{}" viewBox="0 0 {size} {}" font-family="sans-serif" font-size="13">"#,
        size + 40.0,
        size + 40.0
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let step = 10.0;
    let mut g = -(extent / step).floor() * step;
    while g <= extent {
        let (a, _) = page(&[0.0, g]);
        let (_, b) = page(&[g, 0.0]);
        let _ = writeln!(
            s,
            r##"<line x1="{a:.1}" y1="0" x2="{a:.1}" y2="{size}" stroke="#e4e4e4"/><line x1="0" y1="{b:.1}" x2="{size}" y2="{b:.1}" stroke="#e4e4e4"/>"##
        );
        g += step;
    }
    let dots = |s: &mut String, pts: &[[f32; 2]], r: f32, color: &str| {
        let _ = write!(s, r#"<g fill="{color}">"#);
        for p in pts
            .iter()
            .filter(|p| p[0].abs() <= extent && p[1].abs() <= extent)
        {
            let (x, y) = page(p);
            let _ = write!(s, r#"<circle cx="{x:.1}" cy="{y:.1}" r="{r}"/>"#);
        }
        let _ = writeln!(s, "</g>");
    };
    dots(&mut s, &landmarks, 0.8, "#f4b6b6");
    dots(&mut s, &cut_xy, 1.6, "black");
    dots(&mut s, &beam_xy, 2.0, "#d40000");
    let (ox, oy) = page(&[0.0, 0.0]);
    let _ = writeln!(
        s,
        r##"<path d="M{ox:.1},{:.1} l-6,14 l12,0 z" fill="#1f6fd1"/>"##,
        oy - 10.0
    );
    let legend_y = size + 25.0;
    let _ = writeln!(
        s,
        r##"<text x="10" y="{legend_y}"><tspan fill="#d40000">● leveled range scan ({} beams)</tspan>  <tspan fill="black">● horizontal 2D cut ({} points)</tspan>  <tspan fill="#e08080">● landmark points ({})</tspan>  grid 10 m — {}</text>"##,
        beams.len(),
        cut.len(),
        landmarks.len(),
        xml_escape(title)
    );
    s.push_str("</svg>\n");
    s
}

fn xml_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
