//! g2o text (`levelmap optimize GRAPH --format g2o`): `graphio::posegraph::parse`, the function
//! `read(path)` calls on the file's text. What parses is written back as g2o
//! (`posegraph::to_g2o`, the map product) and must parse again to the same graph.
#![no_main]

use graphio::posegraph::{GraphFormat, parse, to_g2o};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // `read` takes the file with `read_to_string`: text that is not UTF-8 never gets here.
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(file) = parse(text, GraphFormat::G2o) else {
        return;
    };
    let written = to_g2o(&file.graph, &file.ids);
    let back = parse(&written, GraphFormat::G2o).expect("written g2o parses");
    assert_eq!(back.ids, file.ids);
    assert_eq!(back.graph.edges.len(), file.graph.edges.len());
    for (b, e) in back.graph.edges.iter().zip(&file.graph.edges) {
        assert_eq!((b.from, b.to, b.kind), (e.from, e.to, e.kind));
        // Information is written exactly; the measurement to 9 decimals.
        assert_eq!(b.information, e.information);
        let (m, n) = (&b.measurement, &e.measurement);
        for (x, y) in [(m.x, n.x), (m.y, n.y), (m.theta, n.theta)] {
            assert!(
                (x - y).abs() <= 1e-9 + 1e-15 * y.abs(),
                "{y} came back as {x}"
            );
        }
    }
});
