//! Reading one MCAP storage file as a stream (memory bounded by the largest
//! chunk, not the file; [`super::Bag::for_each_of`] buffers a file only
//! when its messages are stored out of log-time order): chunks compressed with zstd, lz4 or not at all,
//! each chunk's CRC (where the writer stored one) checked before its
//! messages are used, and a file cut short or damaged read up to its last whole
//! record. The summary section is not needed.

use std::cell::Cell;
use std::collections::HashMap;
use std::io::Read;
use std::rc::Rc;

use mcap::sans_io::LinearReaderOptions;

use super::source::Source;
use super::{BagError, Damage, FileScan, RawVisitor, StoredDefinition, StoredTopic, TopicFilter};

/// The largest record or decompressed chunk read: a damaged length field
/// cannot make the reader allocate more. For a plain file, a chunk's
/// content is at most this many times the file (zstd and lz4 on ROS
/// messages stay well below), between 64 MiB and 1 GiB.
const RECORD_LIMIT_BYTES: usize = 1 << 30;
const RECORD_LIMIT_MIN_BYTES: usize = 64 << 20;
const CHUNK_EXPANSION: usize = 32;

/// Counts the bytes read, to say where a damaged file stops.
struct Counted<R> {
    inner: R,
    bytes: Rc<Cell<u64>>,
}

impl<R: Read> Read for Counted<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.bytes.set(self.bytes.get() + n as u64);
        Ok(n)
    }
}

type Reader = mcap::io::MessageReader<Counted<Box<dyn Read>>>;

fn reader(source: &Source) -> Result<(Reader, Rc<Cell<u64>>), BagError> {
    let bytes = Rc::new(Cell::new(0));
    let limit = if source.compressed() {
        RECORD_LIMIT_BYTES
    } else {
        (source.len() as usize)
            .saturating_mul(CHUNK_EXPANSION)
            .clamp(RECORD_LIMIT_MIN_BYTES, RECORD_LIMIT_BYTES)
    };
    let options = LinearReaderOptions::default()
        // A chunk is checked whole before any of its messages is used: a
        // damaged one yields nothing rather than what decompressed first
        // (where the writer stored a CRC; some rosbag2 presets do not).
        .with_prevalidate_chunk_crcs(true)
        .with_record_length_limit(limit);
    let counted = Counted {
        inner: source.stream()?,
        bytes: bytes.clone(),
    };
    Ok((
        mcap::io::MessageReader::new_with_options(counted, options),
        bytes,
    ))
}

/// Reads every message of the file once: its topics, definitions and
/// counts, and where it is damaged.
pub(super) fn scan(source: &Source) -> Result<FileScan, BagError> {
    let (mut messages, bytes) = reader(source)?;
    let mut scan = FileScan::default();
    let mut per_channel: HashMap<u16, u64> = HashMap::new();
    // Bytes read when the last whole message came out (its chunk is whole).
    let mut good_bytes = 0;
    for m in messages.by_ref() {
        match m {
            Ok(m) => {
                *per_channel.entry(m.channel.id).or_default() += 1;
                scan.add_message(m.log_time);
                good_bytes = bytes.get();
            }
            Err(e) => {
                scan.damage = Some(damage(source, &scan, good_bytes, bytes.get(), &e));
                break;
            }
        }
    }
    // Channels are known once seen, with or without messages; rosbag2
    // numbers them from 0 or 1, and a lookup per possible id is cheap.
    for id in 0..=u16::MAX {
        let Some(ch) = messages.get_channel(id) else {
            continue;
        };
        let (type_name, encoding) = ch
            .schema
            .as_ref()
            .map(|s| (s.name.clone(), s.encoding.clone()))
            .unwrap_or_default();
        if let Some(s) = &ch.schema {
            scan.definitions.push(StoredDefinition {
                type_name: s.name.clone(),
                encoding: s.encoding.clone(),
                data: s.data.to_vec(),
            });
        }
        let count = per_channel.get(&id).copied().unwrap_or(0);
        scan.topics.push(StoredTopic {
            name: ch.topic.clone(),
            type_name,
            serialization_format: ch.message_encoding.clone(),
            definition_encoding: encoding,
            message_count: count,
        });
    }
    Ok(scan)
}

fn damage(
    source: &Source,
    scan: &FileScan,
    good_bytes: u64,
    read_bytes: u64,
    e: &mcap::McapError,
) -> Damage {
    let what = match e {
        mcap::McapError::UnexpectedEof => {
            "the file ends in the middle of a record (the recording was cut short)".to_string()
        }
        mcap::McapError::BadChunkCrc { .. } => format!("a chunk is damaged ({e})"),
        other => other.to_string(),
    };
    Damage {
        path: source.path.clone(),
        messages_read: scan.messages,
        time_range_ns: scan.time_range_ns(),
        position: format!(
            "whole records up to about byte {good_bytes} of {read_bytes}{}",
            if source.compressed() {
                " (decompressed)"
            } else {
                ""
            }
        ),
        reason: what,
    }
}

/// Hands `f` every message up to `limit` (the count the scan read): the
/// position `want` gives its topic (asked once per channel), the log time
/// and the bytes.
pub(super) fn read(
    source: &Source,
    limit: u64,
    want: &mut TopicFilter<'_>,
    f: &mut RawVisitor<'_>,
) -> Result<(), BagError> {
    let (messages, _) = reader(source)?;
    let mut wanted: HashMap<u16, Option<usize>> = HashMap::new();
    for m in messages.take(limit as usize) {
        let m = m.map_err(|e| BagError::File {
            path: source.path.clone(),
            message: format!("reading messages: {e} (the file changed since it was opened?)"),
        })?;
        let k = *wanted
            .entry(m.channel.id)
            .or_insert_with(|| want(&m.channel.topic));
        if let Some(k) = k {
            f(k, m.log_time, &m.data)?;
        }
    }
    Ok(())
}
