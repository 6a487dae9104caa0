//! Compiles proto/levelmap/v1/*.proto with protox (pure Rust, no system `protoc`) and
//! generates the prost types into OUT_DIR/levelmap.v1.rs; the encoded FileDescriptorSet (every
//! file and its imports) goes to OUT_DIR/levelmap.fds, for recordings that embed the schemas.

use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // Read at run time: a build script compiled for one checkout may run for another that
    // shares the target folder.
    let proto_root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR")?).join("../../proto");
    let version_dir = proto_root.join("levelmap/v1");
    println!("cargo:rerun-if-changed={}", proto_root.display());
    println!("cargo:rerun-if-changed={}", version_dir.display());

    let mut files = Vec::new();
    for entry in std::fs::read_dir(&version_dir)? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "proto") {
            println!("cargo:rerun-if-changed={}", path.display());
            files.push(path);
        }
    }
    files.sort();

    let fds = protox::compile(&files, [&proto_root])?;
    // Without the comments: a recording holds the set once per message type.
    let mut embedded = fds.clone();
    for file in &mut embedded.file {
        file.source_code_info = None;
    }
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(
        out_dir.join("levelmap.fds"),
        prost::Message::encode_to_vec(&embedded),
    )?;
    prost_build::Config::new().compile_fds(fds)?;
    Ok(())
}
