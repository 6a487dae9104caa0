//! Pose graphs in text: g2o (`VERTEX_SE2`, `EDGE_SE2`) and TORO (`VERTEX2`, `EDGE2`).
//!
//! g2o: `EDGE_SE2 i j dx dy dθ I11 I12 I13 I22 I23 I33`, the upper triangle of the
//! information of (x, y, θ). TORO: `EDGE2 i j dx dy dθ Ixx Ixy Iyy Iθθ Ixθ Iyθ` (its own
//! order). Vertex ids need not be contiguous; nodes are numbered by increasing id.

use crate::FileError;
use slam::nalgebra::Matrix3;
use slam::{EdgeKind, Pose2, PoseGraph, RelativeEdge, Robust};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// The text formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GraphFormat {
    /// g2o: `VERTEX_SE2`, `EDGE_SE2` (`.g2o`).
    G2o,
    /// TORO: `VERTEX2`, `EDGE2` (`.graph`, `.toro`).
    Toro,
}

impl GraphFormat {
    /// g2o for `.g2o`, TORO for `.graph`.
    pub fn from_extension(path: &Path) -> Option<GraphFormat> {
        match path.extension()?.to_str()? {
            "g2o" => Some(GraphFormat::G2o),
            "graph" | "toro" => Some(GraphFormat::Toro),
            _ => None,
        }
    }
}

/// A pose graph read from a file.
#[derive(Clone, Debug)]
pub struct GraphFile {
    /// The nodes and edges, nodes numbered by increasing vertex id.
    pub graph: PoseGraph,
    /// The file's vertex id of each node.
    pub ids: Vec<i64>,
    /// Whether every node had a vertex line (its pose is then the file's).
    pub has_vertices: bool,
    /// Line number of each edge (for error messages about edges).
    pub edge_lines: Vec<usize>,
}

/// Reads a g2o or TORO file, its format named (`g2o`, `toro`) or, without a name, told by
/// its extension (as a command line's `--format` works).
pub fn read_named(path: &Path, format: Option<&str>) -> Result<GraphFile, FileError> {
    let invalid = |message: String| FileError::Invalid {
        path: path.to_owned(),
        message,
    };
    let format = match format {
        Some("g2o") => GraphFormat::G2o,
        Some("toro") => GraphFormat::Toro,
        Some(other) => {
            return Err(invalid(format!(
                "unknown format {other:?} (expected g2o or toro)"
            )));
        }
        None => GraphFormat::from_extension(path).ok_or_else(|| {
            invalid("cannot tell the format from the extension; pass --format g2o|toro".into())
        })?,
    };
    read(path, format)
}

/// Reads a g2o or TORO file.
pub fn read(path: &Path, format: GraphFormat) -> Result<GraphFile, FileError> {
    let text = std::fs::read_to_string(path).map_err(|source| FileError::Io {
        path: path.to_owned(),
        error: source,
    })?;
    parse(&text, format).map_err(|(line, message)| match line {
        0 => FileError::Invalid {
            path: path.to_owned(),
            message,
        },
        line => FileError::Line {
            path: path.to_owned(),
            line,
            message,
        },
    })
}

/// Parses file text; errors carry the 1-based line (0: the file as a whole).
pub fn parse(text: &str, format: GraphFormat) -> Result<GraphFile, (usize, String)> {
    let (vertex_tag, edge_tag) = match format {
        GraphFormat::G2o => ("VERTEX_SE2", "EDGE_SE2"),
        GraphFormat::Toro => ("VERTEX2", "EDGE2"),
    };
    let mut vertices: BTreeMap<i64, Pose2> = BTreeMap::new();
    let mut raw_edges: Vec<(usize, i64, i64, Pose2, Matrix3<f64>)> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line_no = n + 1;
        let mut fields = line.split_whitespace();
        let Some(tag) = fields.next() else { continue };
        if tag.starts_with('#') {
            continue;
        }
        let rest: Vec<&str> = fields.collect();
        if tag == vertex_tag {
            let (id, v) = numbers(&rest, 4, line_no)?;
            vertices.insert(id, Pose2::new(v[1], v[2], v[3]));
        } else if tag == edge_tag {
            // Both ids first, so that a bad id is reported as one.
            let j = parse_id(rest.get(1).copied().unwrap_or(""), line_no)?;
            let (i, v) = numbers(&rest, 11, line_no)?;
            let (z, info) = match format {
                GraphFormat::G2o => (
                    Pose2::new(v[2], v[3], v[4]),
                    Matrix3::new(v[5], v[6], v[7], v[6], v[8], v[9], v[7], v[9], v[10]),
                ),
                // Ixx Ixy Iyy Iθθ Ixθ Iyθ
                GraphFormat::Toro => (
                    Pose2::new(v[2], v[3], v[4]),
                    Matrix3::new(v[5], v[6], v[9], v[6], v[7], v[10], v[9], v[10], v[8]),
                ),
            };
            raw_edges.push((line_no, i, j, z, info));
        } else if matches!(
            tag,
            "FIX" | "VERTEX_XY" | "EDGE_SE2_XY" | "PARAMS_SE2OFFSET"
        ) && format == GraphFormat::G2o
        {
            if tag != "FIX" {
                return Err((
                    line_no,
                    format!("{tag} is not supported (only SE(2) poses and edges)"),
                ));
            }
        } else {
            return Err((
                line_no,
                format!("unknown element {tag:?}; expected {vertex_tag} or {edge_tag}"),
            ));
        }
    }
    // Nodes: every vertex id and every id an edge names, by increasing id.
    let mut ids: Vec<i64> = vertices.keys().copied().collect();
    ids.extend(raw_edges.iter().flat_map(|e| [e.1, e.2]));
    ids.sort_unstable();
    ids.dedup();
    if ids.is_empty() {
        return Err((0, format!("no {vertex_tag} or {edge_tag} lines")));
    }
    let has_vertices = ids.iter().all(|id| vertices.contains_key(id));
    if !vertices.is_empty() && !has_vertices {
        let missing = ids
            .iter()
            .find(|id| !vertices.contains_key(id))
            .expect("some id lacks a vertex");
        let line = raw_edges
            .iter()
            .find(|e| e.1 == *missing || e.2 == *missing)
            .map_or(0, |e| e.0);
        return Err((
            line,
            format!("edge refers to vertex {missing}, which the file does not define"),
        ));
    }
    let index: BTreeMap<i64, usize> = ids.iter().enumerate().map(|(k, id)| (*id, k)).collect();
    let mut graph = PoseGraph {
        poses: ids
            .iter()
            .map(|id| vertices.get(id).copied().unwrap_or(Pose2::IDENTITY))
            .collect(),
        ..Default::default()
    };
    let mut edge_lines = Vec::with_capacity(raw_edges.len());
    for (line, i, j, z, information) in raw_edges {
        if i == j {
            return Err((line, format!("edge from vertex {i} to itself")));
        }
        if !slam::network::is_information(&information) {
            return Err((
                line,
                "information matrix is not positive definite".to_string(),
            ));
        }
        graph.edges.push(RelativeEdge {
            from: index[&i],
            to: index[&j],
            measurement: z,
            information,
            // Checked: i may be i64::MAX (a file's ids are any integers).
            kind: if i.checked_add(1) == Some(j) {
                EdgeKind::Odometry
            } else {
                EdgeKind::LoopClosure
            },
            robust: Robust::None,
        });
        edge_lines.push(line);
    }
    Ok(GraphFile {
        graph,
        ids,
        has_vertices,
        edge_lines,
    })
}

fn parse_id(field: &str, line: usize) -> Result<i64, (usize, String)> {
    field
        .parse::<i64>()
        .map_err(|_| (line, format!("vertex id {field:?} is not an integer")))
}

/// The id (first field) and the `count − 1` numbers after it, all finite.
fn numbers(fields: &[&str], count: usize, line: usize) -> Result<(i64, Vec<f64>), (usize, String)> {
    if fields.len() < count {
        return Err((
            line,
            format!("expected {count} fields, found {}", fields.len()),
        ));
    }
    let id = parse_id(fields[0], line)?;
    let mut values = Vec::with_capacity(count);
    values.push(id as f64);
    for f in &fields[1..count] {
        let v: f64 = f
            .parse()
            .map_err(|_| (line, format!("{f:?} is not a number")))?;
        if !v.is_finite() {
            return Err((line, format!("{f:?} is not a finite number")));
        }
        values.push(v);
    }
    // values[0] is the id, values[1..] the fields after it (for edges, values[1] is j).
    Ok((id, values))
}

/// Writes the graph as g2o text (vertices, then edges), with the given vertex ids.
pub fn to_g2o(graph: &PoseGraph, ids: &[i64]) -> String {
    let mut s = String::with_capacity(graph.poses.len() * 48 + graph.edges.len() * 120);
    for (p, id) in graph.poses.iter().zip(ids) {
        let _ = writeln!(s, "VERTEX_SE2 {id} {:.9} {:.9} {:.9}", p.x, p.y, p.theta);
    }
    for e in &graph.edges {
        let (z, m) = (&e.measurement, &e.information);
        let _ = writeln!(
            s,
            "EDGE_SE2 {} {} {:.9} {:.9} {:.9} {} {} {} {} {} {}",
            ids[e.from],
            ids[e.to],
            z.x,
            z.y,
            z.theta,
            m[(0, 0)],
            m[(0, 1)],
            m[(0, 2)],
            m[(1, 1)],
            m[(1, 2)],
            m[(2, 2)]
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn g2o_and_toro_orders_give_the_same_information() {
        let g2o = parse("EDGE_SE2 0 1 1 0 0 10 1 2 20 3 30\n", GraphFormat::G2o).unwrap();
        // TORO: Ixx Ixy Iyy Iθθ Ixθ Iyθ
        let toro = parse("EDGE2 0 1 1 0 0 10 1 20 30 2 3\n", GraphFormat::Toro).unwrap();
        assert_eq!(
            g2o.graph.edges[0].information,
            toro.graph.edges[0].information
        );
        assert_eq!(g2o.graph.edges[0].information[(0, 2)], 2.0);
        assert!(!g2o.has_vertices);
    }

    #[test]
    fn bad_lines_are_named() {
        let err = |text: &str| parse(text, GraphFormat::G2o).unwrap_err();
        assert_eq!(err("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 1 0\n").0, 2);
        assert!(
            err("EDGE_SE2 0 1 nan 0 0 1 0 0 1 0 1\n")
                .1
                .contains("finite")
        );
        assert!(
            err("EDGE_SE2 0 1 1 0 0 1 0 0 -1 0 1\n")
                .1
                .contains("positive definite")
        );
        assert!(
            err("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 0\nEDGE_SE2 0 2 1 0 0 1 0 0 1 0 1\n")
                .1
                .contains("vertex 2")
        );
        assert!(err("EDGE3 0 1\n").1.contains("unknown element"));
        assert_eq!(err("EDGE_SE2 0 x 1 0 0 1 0 0 1 0 1\n").0, 1);
    }

    #[test]
    fn extreme_vertex_ids_are_ids() {
        // i64::MAX + 1 overflowed (found by fuzz/, target g2o).
        let text = "EDGE_SE2 9223372036854775807 -9223372036854775808 1 0 0 1 0 0 1 0 1\n";
        let file = parse(text, GraphFormat::G2o).unwrap();
        assert_eq!(file.ids, [i64::MIN, i64::MAX]);
        assert_eq!(file.graph.edges[0].kind, EdgeKind::LoopClosure);
        let toro = parse(
            "EDGE2 9223372036854775806 9223372036854775807 1 0 0 1 0 1 1 0 0\n",
            GraphFormat::Toro,
        )
        .unwrap();
        assert_eq!(toro.graph.edges[0].kind, EdgeKind::Odometry);
    }

    #[test]
    fn g2o_round_trip() {
        let text = "VERTEX_SE2 3 0 0 0\nVERTEX_SE2 7 1 2 0.5\nEDGE_SE2 3 7 1 2 0.5 1 0 0 1 0 1\n";
        let a = parse(text, GraphFormat::G2o).unwrap();
        let b = parse(&to_g2o(&a.graph, &a.ids), GraphFormat::G2o).unwrap();
        assert_eq!(a.ids, b.ids);
        assert_eq!(a.graph, b.graph);
    }
}
