//! rosbag2 recordings in and out, without ROS.
//!
//! [`Bag`] reads a recording as users have it: a bag directory or one
//! storage file; MCAP (chunks zstd, lz4 or plain) or sqlite3 (`.db3`, every
//! table layout from Foxy on); one file or split; whole files compressed
//! with zstd (`--compression-mode file`) or each message
//! (`--compression-mode message`); with `metadata.yaml` (versions 1 to 9) or
//! without it (the recorder did not close: files in the order of their first
//! message). A file cut short or damaged is read up to its last whole
//! record and the damage is reported ([`Bag::damage`]). Message definitions
//! come from the file where it stores them (MCAP schemas, sqlite3
//! `message_definitions`) and from twindrive's standard ones otherwise.
//!
//! [`BagWriter`] writes bags `ros2 bag` plays, in either storage.

mod mcap_read;
mod mcap_write;
pub mod metadata;
mod source;
mod sqlite_read;
mod sqlite_write;
mod storage_write;
mod writer;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use metadata::Metadata;
pub use source::Storage;
pub use storage_write::WriteError;
pub use writer::{BagWriter, TopicId};

use crate::msgs::{self, Distro};
use crate::schema::{Schema, normalize_type_name};
use crate::value::Value;
use source::Source;

/// Reading or writing a bag failed; every variant names the file and, where
/// it applies, the topic and the message's index on that topic (0-based).
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {message}", path.display())]
    File { path: PathBuf, message: String },
    #[error("{}: topic `{topic}`: {message}", path.display())]
    Topic {
        path: PathBuf,
        topic: String,
        message: String,
    },
    #[error("{}: topic `{topic}`, message {index} (log time {log_time_ns} ns): {message}", path.display())]
    Message {
        path: PathBuf,
        topic: String,
        index: u64,
        log_time_ns: u64,
        message: String,
    },
}

/// A topic of a bag.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicInfo {
    pub name: String,
    /// `pkg/msg/Type`.
    pub type_name: String,
    /// How the stored definition is written (`ros2msg`, `ros2idl`), or
    /// empty when the file stores none.
    pub schema_encoding: String,
    /// rosbag2's `serialization_format` (`cdr`).
    pub message_encoding: String,
    /// Messages that can be read (up to any damage).
    pub message_count: u64,
}

/// Where a storage file stops being readable.
#[derive(Debug, Clone, PartialEq)]
pub struct Damage {
    pub path: PathBuf,
    /// Whole messages read before the damage.
    pub messages_read: u64,
    /// Log times of the first and last of them.
    pub time_range_ns: Option<(u64, u64)>,
    /// Where the readable part ends.
    pub position: String,
    pub reason: String,
}

impl std::fmt::Display for Damage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let span = match self.time_range_ns {
            Some((a, b)) => format!(
                ", {:.3} s of recording up to log time {:.3} s",
                (b - a) as f64 * 1e-9,
                b as f64 * 1e-9
            ),
            None => String::new(),
        };
        write!(
            f,
            "{}: cut short or damaged: {}; read {} whole messages{span} ({})",
            self.path.display(),
            self.reason,
            self.messages_read,
            self.position
        )
    }
}

/// A storage file of an opened bag.
#[derive(Debug, Clone, PartialEq)]
pub struct FileInfo {
    pub path: PathBuf,
    pub storage: Storage,
    /// Compressed whole with zstd.
    pub compressed: bool,
    /// Messages that can be read.
    pub message_count: u64,
    /// Log times of the first and last message.
    pub time_range_ns: Option<(u64, u64)>,
    pub size_bytes: u64,
}

/// What a storage file says about one topic.
#[derive(Debug, Clone, Default)]
struct StoredTopic {
    name: String,
    type_name: String,
    serialization_format: String,
    definition_encoding: String,
    message_count: u64,
}

/// A message definition stored in a file.
#[derive(Debug, Clone)]
struct StoredDefinition {
    type_name: String,
    encoding: String,
    data: Vec<u8>,
}

/// Gets a raw message: the topic's position (from a [`TopicFilter`]), the
/// log time and the stored bytes.
type RawVisitor<'a> = dyn FnMut(usize, u64, &[u8]) -> Result<(), BagError> + 'a;
/// A topic's position among those wanted, asked once per topic and file.
type TopicFilter<'a> = dyn FnMut(&str) -> Option<usize> + 'a;

/// One pass over a storage file.
#[derive(Debug, Clone, Default)]
struct FileScan {
    topics: Vec<StoredTopic>,
    definitions: Vec<StoredDefinition>,
    messages: u64,
    first_ns: Option<u64>,
    last_ns: Option<u64>,
    ros_distro: Option<String>,
    /// sqlite3: the row id of the last message read.
    last_row_id: i64,
    /// Some message comes before an earlier-stamped one (chunks that
    /// overlap in time): reading sorts the file's messages first.
    out_of_order: bool,
    last_seen_ns: u64,
    damage: Option<Damage>,
}

impl FileScan {
    fn add_message(&mut self, t_ns: u64) {
        self.messages += 1;
        self.out_of_order |= self.last_seen_ns > t_ns;
        self.last_seen_ns = t_ns;
        self.first_ns = Some(self.first_ns.map_or(t_ns, |a| a.min(t_ns)));
        self.last_ns = Some(self.last_ns.map_or(t_ns, |b| b.max(t_ns)));
    }

    fn time_range_ns(&self) -> Option<(u64, u64)> {
        Some((self.first_ns?, self.last_ns?))
    }
}

/// A storage file, scanned.
struct BagFile {
    source: Source,
    db: Option<sqlite_read::Db>,
    scan: FileScan,
}

/// An opened rosbag2 recording.
pub struct Bag {
    /// What was opened (a directory or a file).
    path: PathBuf,
    storage: Storage,
    metadata: Option<Metadata>,
    /// What could not be used at all: an unreadable `metadata.yaml`, a
    /// file of a split bag with nothing readable.
    notes: Vec<Damage>,
    files: Vec<BagFile>,
    topics: Vec<TopicInfo>,
    /// Stored definitions by type name: (encoding, text), the first file's.
    definitions: BTreeMap<String, (String, Vec<u8>)>,
    /// The distribution the file names, if it does.
    distro: Option<String>,
}

/// A decoded message handed to [`Bag::for_each`].
pub struct MessageRef<'a> {
    /// Index on its topic, counting from 0 across the bag's files.
    pub index: u64,
    pub log_time_ns: u64,
    pub value: &'a Value,
    pub schema: &'a Schema,
}

const METADATA: &str = "metadata.yaml";

impl Bag {
    /// Opens a bag directory or one storage file and reads it once through
    /// (topics, counts, damage).
    pub fn open(path: &Path) -> Result<Self, BagError> {
        let file_err = |p: &Path, message: String| BagError::File {
            path: p.into(),
            message,
        };
        // `BAG/metadata.yaml` names its bag.
        let path = match path.parent() {
            Some(dir) if path.file_name().is_some_and(|n| n == METADATA) => {
                if dir.as_os_str().is_empty() {
                    Path::new(".")
                } else {
                    dir
                }
            }
            _ => path,
        };
        let mut notes: Vec<Damage> = Vec::new();
        let (sources, metadata) = if path.is_dir() {
            locate(path, &mut notes)?
        } else {
            let source = Source::recognise(path)?.ok_or_else(|| {
                file_err(
                    path,
                    "neither an MCAP file nor an SQLite database (a rosbag2 storage file is `.mcap` or `.db3`, possibly with `.zstd`)".into(),
                )
            })?;
            (vec![source], None)
        };
        let storage = sources[0].storage;
        if let Some(other) = sources.iter().find(|s| s.storage != storage) {
            return Err(file_err(
                path,
                format!(
                    "holds both {} and {} files ({}); a bag has one storage",
                    storage.identifier(),
                    other.storage.identifier(),
                    other.path.display()
                ),
            ));
        }
        let mut files = Vec::new();
        let several = sources.len() > 1;
        for source in sources {
            let scanned = match source.storage {
                Storage::Mcap => mcap_read::scan(&source).map(|scan| (None, scan)),
                Storage::Sqlite3 => sqlite_read::Db::prepare(&source).and_then(|db| {
                    let scan = sqlite_read::scan(&source, &db)?;
                    Ok((Some(db), scan))
                }),
            };
            match scanned {
                Ok((db, scan)) => files.push(BagFile { source, db, scan }),
                // One unreadable file of several (a split cut at power
                // loss, an empty file): the others are read.
                Err(e) if several => notes.push(Damage {
                    path: source.path.clone(),
                    messages_read: 0,
                    time_range_ns: None,
                    position: "nothing read from this file".into(),
                    reason: e.to_string(),
                }),
                Err(e) => return Err(e),
            }
        }
        if files.is_empty() {
            let reasons: Vec<String> = notes.iter().map(|d| d.reason.clone()).collect();
            return Err(file_err(
                path,
                format!("no whole message can be read: {}", reasons.join("; ")),
            ));
        }
        if metadata.is_none() {
            // Without metadata.yaml the files go in the order of their
            // first message (the split index in the name breaks ties).
            files.sort_by(|a, b| {
                (
                    a.scan.first_ns.unwrap_or(u64::MAX),
                    split_index(&a.source.path),
                )
                    .cmp(&(
                        b.scan.first_ns.unwrap_or(u64::MAX),
                        split_index(&b.source.path),
                    ))
                    .then_with(|| a.source.path.cmp(&b.source.path))
            });
        }

        let mut topics: Vec<TopicInfo> = Vec::new();
        let mut definitions = BTreeMap::new();
        let mut distro = metadata.as_ref().and_then(|m| m.ros_distro.clone());
        for f in &files {
            for d in &f.scan.definitions {
                definitions
                    .entry(d.type_name.clone())
                    .or_insert_with(|| (d.encoding.clone(), d.data.clone()));
            }
            for t in &f.scan.topics {
                match topics.iter_mut().find(|x| x.name == t.name) {
                    Some(x) => {
                        x.message_count += t.message_count;
                        if x.type_name != t.type_name {
                            return Err(file_err(
                                &f.source.path,
                                format!(
                                    "topic `{}` has type {} here and {} elsewhere in the bag",
                                    t.name, t.type_name, x.type_name
                                ),
                            ));
                        }
                    }
                    None => topics.push(TopicInfo {
                        name: t.name.clone(),
                        type_name: t.type_name.clone(),
                        schema_encoding: t.definition_encoding.clone(),
                        message_encoding: t.serialization_format.clone(),
                        message_count: t.message_count,
                    }),
                }
            }
            if distro.is_none() {
                distro = f.scan.ros_distro.clone();
            }
        }
        for t in &mut topics {
            if t.schema_encoding.is_empty()
                && let Some((encoding, _)) = definitions.get(&t.type_name)
            {
                t.schema_encoding = encoding.clone();
            }
        }
        // Topics metadata.yaml lists that no file holds a message of.
        if let Some(m) = &metadata {
            for t in &m.topics {
                if !topics.iter().any(|x| x.name == t.name) {
                    topics.push(TopicInfo {
                        name: t.name.clone(),
                        type_name: t.type_name.clone(),
                        schema_encoding: String::new(),
                        message_encoding: t.serialization_format.clone(),
                        message_count: 0,
                    });
                }
            }
        }
        topics.sort_by(|a, b| a.name.cmp(&b.name));
        if let Some(d) = files
            .iter()
            .find_map(|f| f.scan.damage.as_ref())
            .or(notes.first())
            && files.iter().all(|f| f.scan.messages == 0)
        {
            return Err(file_err(
                &d.path,
                format!("no whole message can be read: {}", d.reason),
            ));
        }
        Ok(Self {
            path: path.into(),
            storage,
            metadata,
            notes,
            files,
            topics,
            definitions,
            distro,
        })
    }

    pub fn topics(&self) -> &[TopicInfo] {
        &self.topics
    }

    pub fn topic(&self, name: &str) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.name == name)
    }

    /// What was opened: the bag directory or the file. Errors name it.
    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn storage(&self) -> Storage {
        self.storage
    }

    /// `metadata.yaml`, when the bag directory has one.
    pub fn metadata(&self) -> Option<&Metadata> {
        self.metadata.as_ref()
    }

    /// The distribution the bag names (`metadata.yaml` from version 8, the
    /// sqlite3 `schema` table from Humble on).
    pub fn ros_distro(&self) -> Option<&str> {
        self.distro.as_deref()
    }

    /// The storage files in the order they are read.
    pub fn files(&self) -> Vec<FileInfo> {
        self.files
            .iter()
            .map(|f| FileInfo {
                path: f.source.path.clone(),
                storage: f.source.storage,
                compressed: f.source.compressed(),
                message_count: f.scan.messages,
                time_range_ns: f.scan.time_range_ns(),
                size_bytes: f.source.len(),
            })
            .collect()
    }

    /// Where files stop being readable, and what was passed over (an
    /// unreadable `metadata.yaml`, a split file with nothing readable);
    /// empty for a whole recording.
    pub fn damage(&self) -> Vec<&Damage> {
        self.notes
            .iter()
            .chain(self.files.iter().filter_map(|f| f.scan.damage.as_ref()))
            .collect()
    }

    /// Messages that can be read, in every file.
    pub fn message_count(&self) -> u64 {
        self.files.iter().map(|f| f.scan.messages).sum()
    }

    /// Log times of the first and last message.
    pub fn time_range_ns(&self) -> Option<(u64, u64)> {
        let first = self.files.iter().filter_map(|f| f.scan.first_ns).min()?;
        let last = self.files.iter().filter_map(|f| f.scan.last_ns).max()?;
        Some((first, last))
    }

    /// What `topic` lists when it is missing: every topic with its type.
    pub fn describe_topics(&self) -> String {
        self.topics
            .iter()
            .map(|t| format!("{} ({}, {} messages)", t.name, t.type_name, t.message_count))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The schema of `topic`: the definition stored in the file, else
    /// twindrive's own of the type.
    pub fn schema(&self, topic: &str) -> Result<Schema, BagError> {
        let terr = |message: String| BagError::Topic {
            path: self.path().to_path_buf(),
            topic: topic.to_string(),
            message,
        };
        let info = self.topic(topic).ok_or_else(|| {
            terr(format!(
                "not in the bag; it has: {}",
                self.describe_topics()
            ))
        })?;
        if info.message_encoding != "cdr" {
            return Err(terr(format!(
                "messages are encoded as `{}`, expected `cdr` (a rosbag2 recording)",
                info.message_encoding
            )));
        }
        let name = &info.type_name;
        if name.is_empty() {
            return Err(terr(
                "the file gives it no type (an MCAP channel without a schema)".into(),
            ));
        }
        let distro = match self.distro.as_deref().and_then(Distro::of_release) {
            Some(d) => d,
            // Bags that store no definitions come from Humble or earlier.
            None if self.definitions.is_empty() => Distro::Humble,
            None => Distro::Jazzy,
        };
        let normal = normalize_type_name(name);
        let builtin = msgs::definition(&normal, distro);
        match self.definitions.get(name) {
            Some((encoding, data)) if encoding == "ros2msg" && !data.is_empty() => {
                let text = std::str::from_utf8(data)
                    .map_err(|_| terr("the message definition is not UTF-8 text".into()))?;
                return Schema::parse(name, text)
                    .map_err(|e| terr(format!("the stored definition of {name}: {e}")));
            }
            Some((encoding, _)) if encoding == "ros2idl" && builtin.is_none() => {
                return Err(terr(format!(
                    "the type {name} is defined as `{encoding}`, and only `ros2msg` definitions are read (IDL-only types are not supported)"
                )));
            }
            // Stored as IDL, or without a usable definition (`unknown`,
            // empty): the built-in one, if twindrive has it.
            _ => {}
        }
        let text = builtin.ok_or_else(|| {
            terr(format!(
                "the bag stores no definition of {name} (sqlite3 bags before ROS 2 Iron keep only type names) and twindrive has no built-in one; built in: {}",
                msgs::known_types().collect::<Vec<_>>().join(", ")
            ))
        })?;
        Schema::parse(&normal, &text)
            .map_err(|e| terr(format!("the built-in definition of {name}: {e}")))
    }

    /// Decodes every message of `topic` in log-time order and hands it to
    /// `f`; an error from the decoder or from `f` names the topic and the
    /// message's index. Returns how many there were.
    pub fn for_each(
        &self,
        topic: &str,
        mut f: impl FnMut(MessageRef<'_>) -> Result<(), String>,
    ) -> Result<u64, BagError> {
        Ok(self.for_each_of(&[topic], |_, m| f(m))?[0])
    }

    /// Decodes every message of any of `topics` in one pass over the bag,
    /// in log-time order within each file (files in order; a file whose
    /// messages are stored out of order is sorted first), and hands `f`
    /// the topic's position in `topics` and the message. Returns the count
    /// per topic.
    pub fn for_each_of(
        &self,
        topics: &[&str],
        mut f: impl FnMut(usize, MessageRef<'_>) -> Result<(), String>,
    ) -> Result<Vec<u64>, BagError> {
        let schemas = topics
            .iter()
            .map(|t| self.schema(t))
            .collect::<Result<Vec<_>, _>>()?;
        let mut counts = vec![0u64; topics.len()];
        let mut batch: Vec<(u64, usize, Vec<u8>)> = Vec::new();
        for file in &self.files {
            let mut deliver = |k: usize, log_time_ns: u64, data: &[u8]| {
                let (schema, index) = (&schemas[k], counts[k]);
                let merr = |message: String| BagError::Message {
                    path: file.source.path.clone(),
                    topic: topics[k].to_string(),
                    index,
                    log_time_ns,
                    message,
                };
                let data = source::message_bytes(data).map_err(merr)?;
                let value = schema.decode(&data).map_err(|e| {
                    merr(format!(
                        "{} does not decode: {}",
                        schema.root().name,
                        e.message
                    ))
                })?;
                f(
                    k,
                    MessageRef {
                        index,
                        log_time_ns,
                        value: &value,
                        schema,
                    },
                )
                .map_err(merr)?;
                counts[k] += 1;
                Ok(())
            };
            let mut want = |name: &str| topics.iter().position(|t| *t == name);
            if !file.scan.out_of_order {
                // Already in log-time order: decoded as read.
                self.read_file(file, &mut want, &mut deliver)?;
                continue;
            }
            // Chunks overlap in time: the file's messages are used in
            // log-time order (a stable sort keeps each topic's own order on
            // ties).
            batch.clear();
            self.read_file(file, &mut want, &mut |k, t, data| {
                batch.push((t, k, data.to_vec()));
                Ok(())
            })?;
            batch.sort_by_key(|(t, _, _)| *t);
            for (t, k, data) in batch.drain(..) {
                deliver(k, t, &data)?;
            }
        }
        Ok(counts)
    }
}

impl Bag {
    /// Hands `f` the messages of `file` up to any damage, in storage order.
    fn read_file(
        &self,
        file: &BagFile,
        want: &mut TopicFilter<'_>,
        f: &mut RawVisitor<'_>,
    ) -> Result<(), BagError> {
        match &file.db {
            None => mcap_read::read(&file.source, file.scan.messages, want, f),
            Some(db) => sqlite_read::read(&file.source, db, file.scan.last_row_id, want, f),
        }
    }
}

/// The storage files of a bag directory and its `metadata.yaml`, if any.
fn locate(
    dir: &Path,
    notes: &mut Vec<Damage>,
) -> Result<(Vec<Source>, Option<Metadata>), BagError> {
    let file_err = |message: String| BagError::File {
        path: dir.into(),
        message,
    };
    let meta_path = dir.join(METADATA);
    // A metadata.yaml that does not read (empty after a crash, a version
    // from the future) is passed over: the files are found as without one.
    let metadata = if meta_path.is_file() {
        match Metadata::read(&meta_path) {
            Ok(m) => Some(m),
            Err(e) => {
                notes.push(Damage {
                    path: meta_path.clone(),
                    messages_read: 0,
                    time_range_ns: None,
                    position:
                        "ignored; the storage files are read in the order of their first message"
                            .into(),
                    reason: e.to_string(),
                });
                None
            }
        }
    } else {
        None
    };
    if let Some(m) = metadata {
        let storage =
            Storage::from_identifier(&m.storage_identifier).ok_or_else(|| BagError::File {
                path: meta_path.clone(),
                message: format!(
                    "storage_identifier `{}`: twindrive reads the `mcap` and `sqlite3` storages",
                    m.storage_identifier
                ),
            })?;
        let mode = m.compression_mode.to_ascii_lowercase();
        if !matches!(mode.as_str(), "" | "none")
            && !matches!(m.compression_format.as_str(), "" | "zstd")
        {
            return Err(BagError::File {
                path: meta_path.clone(),
                message: format!(
                    "compression_format `{}`: rosbag2 compresses with zstd, and twindrive reads zstd",
                    m.compression_format
                ),
            });
        }
        if m.relative_file_paths.is_empty() {
            return Err(BagError::File {
                path: meta_path,
                message: "relative_file_paths lists no storage file".into(),
            });
        }
        let mut sources = Vec::new();
        for listed in &m.relative_file_paths {
            // Older versions wrote `bag_name/bag_name_0.db3`: the file name
            // is what counts.
            let name = Path::new(listed).file_name().unwrap_or(listed.as_ref());
            let p = dir.join(name);
            if !p.is_file() {
                return Err(BagError::File {
                    path: meta_path.clone(),
                    message: format!(
                        "relative_file_paths lists `{listed}`, which is not in {}",
                        dir.display()
                    ),
                });
            }
            let source = Source::recognise(&p)?.ok_or_else(|| BagError::File {
                path: p.clone(),
                message: format!(
                    "metadata.yaml lists it as a {} storage file, but it is neither an MCAP file nor an SQLite database",
                    storage.identifier()
                ),
            })?;
            if source.storage != storage {
                return Err(BagError::File {
                    path: p,
                    message: format!(
                        "metadata.yaml says the storage is {}, but this is a{} {} file",
                        storage.identifier(),
                        if source.storage == Storage::Mcap {
                            "n"
                        } else {
                            ""
                        },
                        source.storage.identifier()
                    ),
                });
            }
            sources.push(source);
        }
        return Ok((sources, Some(m)));
    }
    let mut sources = Vec::new();
    let entries = std::fs::read_dir(dir).map_err(|e| BagError::Io {
        path: dir.into(),
        source: e,
    })?;
    for e in entries {
        let p = e
            .map_err(|e| BagError::Io {
                path: dir.into(),
                source: e,
            })?
            .path();
        let name = p.file_name().unwrap_or_default().to_string_lossy();
        let named = [".mcap", ".db3", ".mcap.zstd", ".db3.zstd"]
            .iter()
            .any(|x| name.ends_with(x));
        if named && p.is_file() {
            sources.extend(Source::recognise(&p)?);
        }
    }
    // A recorder that compresses each finished file and then deletes it
    // can leave both when it stops in between: the plain one is whole.
    let plain: Vec<PathBuf> = sources
        .iter()
        .filter(|s| !s.compressed())
        .map(|s| s.path.clone())
        .collect();
    sources.retain(|s| {
        let twin = s
            .path
            .to_string_lossy()
            .strip_suffix(".zstd")
            .map(PathBuf::from);
        !(s.compressed() && twin.is_some_and(|t| plain.contains(&t)))
    });
    if sources.is_empty() {
        return Err(file_err(
            "a directory without metadata.yaml and without storage files (.mcap, .db3, or either with .zstd): not a rosbag2 bag".into(),
        ));
    }
    Ok((sources, None))
}

/// `n` of a rosbag2 file name `name_n.db3` / `name_n.mcap(.zstd)`.
fn split_index(path: &Path) -> u64 {
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    let name = name.strip_suffix(".zstd").unwrap_or(&name);
    let stem = name.rsplit_once('.').map_or(name, |(stem, _)| stem);
    stem.rsplit('_')
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or(0)
}

#[cfg(test)]
mod tests;
