use super::*;
use std::io::Cursor;

fn odometry(stamp_ns: u64) -> Vec<u8> {
    v1::Odometry {
        header: Some(v1::Header::new("park", "r1", 1, stamp_ns, stamp_ns + 5)),
        ..Default::default()
    }
    .encode_to_vec()
}

/// A recording of `n` odometry messages and one map poses message, in memory.
fn recording(n: u64) -> Vec<u8> {
    let mut writer = RecordingWriter::new(Cursor::new(Vec::new())).unwrap();
    for i in 0..n {
        let key = "levelmap/park/robots/r1/odom";
        assert!(writer.write(key, &odometry(1_000 + i), 2_000 + i).unwrap());
    }
    let poses = v1::MapPoses::default().encode_to_vec();
    assert!(
        writer
            .write("levelmap/park/map/poses", &poses, 9_000)
            .unwrap()
    );
    assert!(!writer.write("levelmap/park/map/grid", b"x", 9_001).unwrap());
    writer.finish().unwrap().into_inner()
}

#[test]
fn messages_read_back_in_order_with_their_keys_and_times() {
    let bytes = recording(3);
    let read: Vec<RecordedMessage> = RecordingReader::new(Cursor::new(&bytes), Path::new("r.mcap"))
        .collect::<anyhow::Result<_>>()
        .unwrap();
    assert_eq!(read.len(), 4);
    assert_eq!(read[0].key, "levelmap/park/robots/r1/odom");
    assert_eq!(read[0].payload, odometry(1_000));
    assert_eq!(read[2].log_time_ns, 2_002);
    assert_eq!(read[3].key, "levelmap/park/map/poses");
}

#[test]
fn channels_name_their_protobuf_type_and_embed_the_descriptor_set() {
    let bytes = recording(2);
    let messages: Vec<_> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    let first = &messages[0];
    let schema = first.channel.schema.as_ref().unwrap();
    assert_eq!(schema.name, "levelmap.v1.Odometry");
    assert_eq!(schema.encoding, "protobuf");
    assert_eq!(&schema.data[..], DESCRIPTOR_SET);
    assert_eq!(first.channel.message_encoding, "protobuf");
    // The header's stamp is the publish time; the receive time the log time.
    assert_eq!((first.publish_time, first.log_time), (1_000, 2_000));
    let poses = &messages[2];
    assert_eq!(poses.publish_time, poses.log_time, "MapPoses has no header");
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    assert!(!summary.chunk_indexes.is_empty());
    assert_eq!(summary.stats.unwrap().message_count, 3);
}

#[test]
fn a_file_cut_mid_chunk_ends_with_an_error_naming_it() {
    let bytes = recording(200);
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    let [chunk] = &summary.chunk_indexes[..] else {
        panic!("one chunk holds every message")
    };
    let cut = &bytes[..(chunk.chunk_start_offset + chunk.chunk_length / 2) as usize];
    let mut reader = RecordingReader::new(Cursor::new(cut), Path::new("cut.mcap"));
    let error = reader.find_map(Result::err).expect("an error");
    let message = error.to_string();
    assert!(message.starts_with("cut.mcap: cut short"), "{message}");
    assert!(
        message.contains(&format!("({} bytes read)", cut.len())),
        "{message}"
    );
    assert!(reader.next().is_none(), "nothing after the error");
    assert!(reader.messages() < 200, "{} messages", reader.messages());
}

#[test]
fn a_damaged_record_length_is_an_error_not_an_allocation() {
    let mut bytes = recording(3);
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    // A record is its opcode, then its length (u64, little-endian).
    let at = summary.chunk_indexes[0].chunk_start_offset as usize + 1;
    bytes[at..at + 8].copy_from_slice(&(1u64 << 40).to_le_bytes());
    let mut reader = RecordingReader::new(Cursor::new(&bytes), Path::new("big.mcap"));
    let error = reader.find_map(Result::err).expect("an error");
    assert!(error.to_string().starts_with("big.mcap: "), "{error}");
}
