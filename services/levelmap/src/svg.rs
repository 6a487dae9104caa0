//! SVG pictures of leveled scans, as the paper's Fig. 4: the leveled range scan (red) over
//! what a fixed horizontal 2D scanner at the sensor sees (black).

use leveling::{Leveled, PointClass, Scan3d, horizontal_cut};
use std::fmt::Write;

/// Half-width of the elevation band taken as the horizontal 2D cut.
const CUT_ELEVATION_RAD: f32 = 0.5 * std::f32::consts::PI / 180.0;

/// Width of the picture's longer side (px).
const SIZE_PX: f32 = 900.0;

/// Fig. 4 for one scan: landmark points (pink), the fixed 2D cut (black), leveled beams (red),
/// a 10 m grid and the sensor (blue, at scan start). x forward points up the page.
pub fn fig4(raw: &Scan3d, leveled: &Leveled, title: &str) -> String {
    let polar = |&(phi, r): &(f32, f32)| [r * phi.cos(), r * phi.sin()];
    let cut: Vec<[f32; 2]> = horizontal_cut(raw, CUT_ELEVATION_RAD)
        .iter()
        .map(polar)
        .collect();
    let beams: Vec<[f32; 2]> = leveled
        .scan
        .returns()
        .collect::<Vec<_>>()
        .iter()
        .map(polar)
        .collect();
    let landmarks = landmark_points(leveled);

    // View: the 1st–99th percentile box of beams and cut, with the sensor; equal scale.
    let bounds = |axis: usize| {
        let mut v: Vec<f32> = beams
            .iter()
            .chain(&cut)
            .map(|p| p[axis])
            .chain([0.0])
            .collect();
        v.sort_by(f32::total_cmp);
        (
            v[v.len() / 100].min(0.0) - 2.0,
            v[v.len() - 1 - v.len() / 100].max(0.0) + 2.0,
        )
    };
    let ((x_lo, x_hi), (y_lo, y_hi)) = (bounds(0), bounds(1));
    let scale = SIZE_PX / (x_hi - x_lo).max(y_hi - y_lo).max(10.0);
    let (width, height) = ((y_hi - y_lo) * scale, (x_hi - x_lo) * scale);
    let inside = |p: &[f32; 2]| p[0] >= x_lo && p[0] <= x_hi && p[1] >= y_lo && p[1] <= y_hi;
    // Page coordinates: x forward → up, y left → left.
    let page = |p: &[f32; 2]| ((y_hi - p[1]) * scale, (x_hi - p[0]) * scale);

    let (page_w, page_h) = (width.max(420.0), height + 42.0);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{page_w:.0}" height="{page_h:.0}" viewBox="0 0 {page_w:.0} {page_h:.0}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, "<title>{}</title>", xml_escape(title));
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let grid_m = 10.0;
    let mut g = (x_lo / grid_m).ceil() * grid_m;
    while g <= x_hi {
        let (_, y) = page(&[g, 0.0]);
        let _ = writeln!(
            s,
            r##"<line x1="0" y1="{y:.1}" x2="{width:.1}" y2="{y:.1}" stroke="#e4e4e4"/>"##
        );
        g += grid_m;
    }
    let mut g = (y_lo / grid_m).ceil() * grid_m;
    while g <= y_hi {
        let (x, _) = page(&[0.0, g]);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="0" x2="{x:.1}" y2="{height:.1}" stroke="#e4e4e4"/>"##
        );
        g += grid_m;
    }
    let dots = |s: &mut String, points: &[[f32; 2]], radius: f32, color: &str| {
        let _ = write!(s, r#"<g fill="{color}">"#);
        for p in points.iter().filter(|p| inside(p)) {
            let (x, y) = page(p);
            let _ = write!(s, r#"<circle cx="{x:.1}" cy="{y:.1}" r="{radius}"/>"#);
        }
        let _ = writeln!(s, "</g>");
    };
    dots(&mut s, &landmarks, 0.8, "#f4b6b6");
    dots(&mut s, &cut, 2.4, "black");
    dots(&mut s, &beams, 1.4, "#e00000");
    let (ox, oy) = page(&[0.0, 0.0]);
    let _ = writeln!(
        s,
        r##"<path d="M{ox:.1},{:.1} l-6,14 l12,0 z" fill="#1f6fd1"/>"##,
        oy - 10.0
    );
    let _ = writeln!(
        s,
        r##"<text x="8" y="{:.0}"><tspan fill="#e00000">● leveled range scan ({} beams)</tspan>  ● horizontal 2D cut ({} points)</text>"##,
        height + 18.0,
        beams.len(),
        cut.len(),
    );
    let _ = writeln!(
        s,
        r##"<text x="8" y="{:.0}"><tspan fill="#e08080">● landmark points ({})</tspan>  grid {grid_m} m, sensor at scan start in blue</text>"##,
        height + 34.0,
        landmarks.len(),
    );
    s.push_str("</svg>\n");
    s
}

/// Every landmark point, projected onto the leveled frame's horizontal plane (x, y in m).
fn landmark_points(leveled: &Leveled) -> Vec<[f32; 2]> {
    let cloud = &leveled.cloud;
    cloud
        .columns
        .iter()
        .flat_map(|c| {
            let range = c.start as usize..(c.start + c.len) as usize;
            cloud.points[range.clone()]
                .iter()
                .zip(&leveled.classes[range])
                .filter(|(_, class)| **class == PointClass::Landmark)
                .map(move |(p, _)| {
                    let [x, y, _] = p.to_xyz();
                    [x + c.origin_xy_m[0], y + c.origin_xy_m[1]]
                })
        })
        .collect()
}

fn xml_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
