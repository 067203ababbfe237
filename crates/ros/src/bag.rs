//! rosbag2 recordings in MCAP storage: reading any topic with the message
//! definitions stored in the file, and writing bags that `ros2 bag` plays
//! (profile `ros2`, schemas `ros2msg`, messages `cdr`, the offered QoS in
//! each channel's metadata, and the `metadata.yaml` text).

use std::collections::BTreeMap;
use std::io::{Seek, Write};
use std::path::{Path, PathBuf};

use crate::msgs::{self, Distro, RosMessage};
use crate::qos::Qos;
use crate::schema::Schema;
use crate::value::Value;

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
#[derive(Debug, Clone)]
pub struct TopicInfo {
    pub name: String,
    /// `pkg/msg/Type`.
    pub type_name: String,
    pub schema_encoding: String,
    pub message_encoding: String,
    pub message_count: u64,
}

/// One MCAP file of a bag, read into memory.
struct BagFile {
    path: PathBuf,
    bytes: Vec<u8>,
}

/// An opened rosbag2 recording: one `.mcap` file, or a bag directory (its
/// `.mcap` files in split order).
pub struct Bag {
    files: Vec<BagFile>,
    topics: Vec<TopicInfo>,
    /// Each topic's stored definition (type name, `ros2msg` text), from
    /// the first file that has it.
    definitions: BTreeMap<String, (String, Vec<u8>)>,
}

/// A decoded message handed to [`Bag::for_each`].
pub struct MessageRef<'a> {
    /// Index on its topic, counting from 0 across the bag's files.
    pub index: u64,
    pub log_time_ns: u64,
    pub value: &'a Value,
    pub schema: &'a Schema,
}

impl Bag {
    pub fn open(path: &Path) -> Result<Self, BagError> {
        let io = |p: &Path, e| BagError::Io {
            path: p.to_path_buf(),
            source: e,
        };
        let paths = if path.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(path)
                .map_err(|e| io(path, e))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
                .collect();
            // `name_0.mcap`, `name_1.mcap`, … `name_10.mcap`: split order.
            found.sort_by_key(|p| (p.as_os_str().len(), p.clone()));
            if found.is_empty() {
                return Err(BagError::File {
                    path: path.into(),
                    message: "a bag directory, but it holds no .mcap file (only MCAP storage is read; convert sqlite3 bags with `ros2 bag convert`)".into(),
                });
            }
            found
        } else {
            vec![path.to_path_buf()]
        };
        let mut files = Vec::new();
        let mut topics: BTreeMap<String, TopicInfo> = BTreeMap::new();
        let mut definitions = BTreeMap::new();
        for p in paths {
            let bytes = std::fs::read(&p).map_err(|e| io(&p, e))?;
            let bad = |message: String| BagError::File {
                path: p.clone(),
                message,
            };
            const CUT_SHORT: &str = "if the recording was cut short, `mcap recover` (the MCAP command-line tool) repairs it";
            let summary = mcap::Summary::read(&bytes)
                .map_err(|e| bad(format!("not a readable MCAP file ({e}); {CUT_SHORT}")))?
                .ok_or_else(|| bad(format!("the MCAP file has no summary section; {CUT_SHORT}")))?;
            let counts = summary
                .stats
                .as_ref()
                .map(|s| s.channel_message_counts.clone())
                .unwrap_or_default();
            for (id, ch) in &summary.channels {
                let (type_name, schema_encoding) = ch
                    .schema
                    .as_ref()
                    .map(|s| (s.name.clone(), s.encoding.clone()))
                    .unwrap_or_default();
                let entry = topics.entry(ch.topic.clone()).or_insert_with(|| TopicInfo {
                    name: ch.topic.clone(),
                    type_name,
                    schema_encoding,
                    message_encoding: ch.message_encoding.clone(),
                    message_count: 0,
                });
                entry.message_count += counts.get(id).copied().unwrap_or(0);
                if let Some(schema) = &ch.schema {
                    definitions
                        .entry(ch.topic.clone())
                        .or_insert_with(|| (schema.name.clone(), schema.data.to_vec()));
                }
            }
            files.push(BagFile { path: p, bytes });
        }
        Ok(Self {
            files,
            topics: topics.into_values().collect(),
            definitions,
        })
    }

    pub fn topics(&self) -> &[TopicInfo] {
        &self.topics
    }

    pub fn topic(&self, name: &str) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.name == name)
    }

    /// The path errors name: the first file.
    pub fn path(&self) -> &Path {
        &self.files[0].path
    }

    /// What `topic` lists when it is missing: every topic with its type.
    pub fn describe_topics(&self) -> String {
        self.topics
            .iter()
            .map(|t| format!("{} ({}, {} messages)", t.name, t.type_name, t.message_count))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The schema of `topic`, parsed from the definition stored in the file.
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
        if info.schema_encoding != "ros2msg" {
            return Err(terr(format!(
                "the type {} is defined as `{}`, and only `ros2msg` definitions are read (IDL-only types are not supported)",
                info.type_name, info.schema_encoding
            )));
        }
        let (name, data) = self
            .definitions
            .get(topic)
            .ok_or_else(|| terr("has no schema".into()))?;
        let text = std::str::from_utf8(data)
            .map_err(|_| terr("the message definition is not UTF-8 text".into()))?;
        Schema::parse(name, text).map_err(|e| terr(format!("the stored definition of {name}: {e}")))
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
    /// in log-time order, and hands `f` the topic's position in `topics`
    /// and the message. Returns the count per topic.
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
        for file in &self.files {
            let stream = mcap::MessageStream::new(&file.bytes).map_err(|e| BagError::File {
                path: file.path.clone(),
                message: e.to_string(),
            })?;
            // Channel id → position in `topics`, learnt as channels appear.
            let mut wanted: std::collections::HashMap<u16, Option<usize>> = Default::default();
            let mut batch: Vec<(u64, usize, Vec<u8>)> = Vec::new();
            for m in stream {
                let m = m.map_err(|e| BagError::File {
                    path: file.path.clone(),
                    message: format!("reading messages: {e}"),
                })?;
                let k = *wanted
                    .entry(m.channel.id)
                    .or_insert_with(|| topics.iter().position(|t| *t == m.channel.topic));
                if let Some(k) = k {
                    batch.push((m.log_time, k, m.data.into_owned()));
                }
            }
            // Chunks may overlap in time; messages are used in log-time
            // order (a stable sort keeps each topic's own order on ties).
            batch.sort_by_key(|(t, _, _)| *t);
            for (log_time_ns, k, data) in batch {
                let (schema, index) = (&schemas[k], counts[k]);
                let merr = |message: String| BagError::Message {
                    path: file.path.clone(),
                    topic: topics[k].to_string(),
                    index,
                    log_time_ns,
                    message,
                };
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
            }
        }
        Ok(counts)
    }
}

/// A topic handle from [`BagWriter::topic`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicId(usize);

struct WrittenTopic {
    name: String,
    type_name: &'static str,
    /// RIHS01 (Jazzy on; Humble has no type hashes).
    type_hash: String,
    qos: Qos,
    channel: u16,
    count: u64,
}

/// Writes one `.mcap` file of a rosbag2 bag.
pub struct BagWriter<W: Write + Seek> {
    mcap: mcap::Writer<W>,
    distro: Distro,
    file_name: String,
    topics: Vec<WrittenTopic>,
    /// Per type: its schema id and its type hash (empty for Humble).
    schemas: BTreeMap<&'static str, (u16, String)>,
    time_range: Option<(u64, u64)>,
    buf: Vec<u8>,
}

impl<W: Write + Seek> BagWriter<W> {
    /// `file_name` is how `metadata.yaml` refers to this file.
    pub fn new(w: W, file_name: &str, distro: Distro) -> mcap::McapResult<Self> {
        let mcap = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("twindrive-ros ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .create(w)?;
        Ok(Self {
            mcap,
            distro,
            file_name: file_name.to_string(),
            topics: Vec::new(),
            schemas: BTreeMap::new(),
            time_range: None,
            buf: Vec::new(),
        })
    }

    /// Declares `name` with messages of type `T`.
    pub fn topic<T: RosMessage>(&mut self, name: &str, qos: Qos) -> mcap::McapResult<TopicId> {
        let (schema, type_hash) = match self.schemas.get(T::TYPE) {
            Some(known) => known.clone(),
            None => {
                let text = msgs::definition(T::TYPE, self.distro)
                    .expect("every RosMessage has a definition");
                let id = self.mcap.add_schema(T::TYPE, "ros2msg", text.as_bytes())?;
                let hash = match self.distro {
                    Distro::Humble => String::new(),
                    Distro::Jazzy => {
                        msgs::type_hash(T::TYPE).expect("the built-in definitions parse")
                    }
                };
                self.schemas.insert(T::TYPE, (id, hash.clone()));
                (id, hash)
            }
        };
        let mut meta = BTreeMap::new();
        meta.insert("offered_qos_profiles".to_string(), qos.yaml());
        if !type_hash.is_empty() {
            meta.insert("topic_type_hash".to_string(), type_hash.clone());
        }
        let channel = self.mcap.add_channel(schema, name, "cdr", &meta)?;
        self.topics.push(WrittenTopic {
            name: name.to_string(),
            type_name: T::TYPE,
            type_hash,
            qos,
            channel,
            count: 0,
        });
        Ok(TopicId(self.topics.len() - 1))
    }

    /// Writes `msg` on `topic`, received (and published) at `t_ns`.
    pub fn write<T: RosMessage>(
        &mut self,
        topic: TopicId,
        t_ns: u64,
        msg: &T,
    ) -> mcap::McapResult<()> {
        let t = &mut self.topics[topic.0];
        debug_assert_eq!(
            t.type_name,
            T::TYPE,
            "topic {} written with another type",
            t.name
        );
        msgs::encode_into(&mut self.buf, msg);
        self.mcap.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: t.channel,
                sequence: t.count as u32,
                log_time: t_ns,
                publish_time: t_ns,
            },
            &self.buf,
        )?;
        t.count += 1;
        self.time_range = Some(match self.time_range {
            None => (t_ns, t_ns),
            Some((a, b)) => (a.min(t_ns), b.max(t_ns)),
        });
        Ok(())
    }

    /// Each topic with its type and the number of messages written so far.
    pub fn topic_counts(&self) -> Vec<(String, &'static str, u64)> {
        self.topics
            .iter()
            .map(|t| (t.name.clone(), t.type_name, t.count))
            .collect()
    }

    /// Finishes the file and returns the `metadata.yaml` text for the bag
    /// directory it goes in.
    pub fn finish(mut self) -> mcap::McapResult<String> {
        let yaml = self.metadata_yaml();
        let mut meta = BTreeMap::new();
        meta.insert("serialized_metadata".to_string(), yaml.clone());
        meta.insert("ROS_DISTRO".to_string(), self.distro.name().to_string());
        self.mcap.write_metadata(&mcap::records::Metadata {
            name: "rosbag2".into(),
            metadata: meta,
        })?;
        self.mcap.finish()?;
        Ok(yaml)
    }

    fn metadata_yaml(&self) -> String {
        use std::fmt::Write as _;
        let (start, end) = self.time_range.unwrap_or((0, 0));
        let duration = end - start;
        let total: u64 = self.topics.iter().map(|t| t.count).sum();
        let quote = |s: &str| serde_json::to_string(s).expect("a string");
        let mut y = String::new();
        let _ = writeln!(y, "rosbag2_bagfile_information:");
        let _ = writeln!(y, "  version: 8");
        let _ = writeln!(y, "  storage_identifier: mcap");
        let _ = writeln!(y, "  duration:\n    nanoseconds: {duration}");
        let _ = writeln!(y, "  starting_time:\n    nanoseconds_since_epoch: {start}");
        let _ = writeln!(y, "  message_count: {total}");
        let _ = writeln!(y, "  topics_with_message_count:");
        for t in &self.topics {
            let _ = writeln!(y, "    - topic_metadata:");
            let _ = writeln!(y, "        name: {}", quote(&t.name));
            let _ = writeln!(y, "        type: {}", t.type_name);
            let _ = writeln!(y, "        serialization_format: cdr");
            let _ = writeln!(y, "        offered_qos_profiles: {}", quote(&t.qos.yaml()));
            let _ = writeln!(y, "        type_description_hash: {}", quote(&t.type_hash));
            let _ = writeln!(y, "      message_count: {}", t.count);
        }
        let _ = writeln!(y, "  compression_format: \"\"");
        let _ = writeln!(y, "  compression_mode: \"\"");
        let _ = writeln!(
            y,
            "  relative_file_paths:\n    - {}",
            quote(&self.file_name)
        );
        let _ = writeln!(y, "  files:");
        let _ = writeln!(y, "    - path: {}", quote(&self.file_name));
        let _ = writeln!(
            y,
            "      starting_time:\n        nanoseconds_since_epoch: {start}"
        );
        let _ = writeln!(y, "      duration:\n        nanoseconds: {duration}");
        let _ = writeln!(y, "      message_count: {total}");
        let _ = writeln!(y, "  custom_data: ~");
        let _ = writeln!(y, "  ros_distro: {}", self.distro.name());
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::{Header, JointState, Pose, PoseStamped};

    fn write_bag(dir: &Path) -> PathBuf {
        let path = dir.join("b_0.mcap");
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut w = BagWriter::new(file, "b_0.mcap", Distro::Jazzy).unwrap();
        let js = w
            .topic::<JointState>("/joint_states", Qos::DEFAULT)
            .unwrap();
        let pose = w.topic::<PoseStamped>("/pose", Qos::DEFAULT).unwrap();
        for k in 0..5u64 {
            let t = 1_000_000_000 + k * 10_000_000;
            w.write(
                js,
                t,
                &JointState {
                    header: Header::new(t, ""),
                    name: vec!["l".into(), "r".into()],
                    position: vec![k as f64, -(k as f64)],
                    velocity: vec![],
                    effort: vec![],
                },
            )
            .unwrap();
            w.write(
                pose,
                t,
                &PoseStamped {
                    header: Header::new(t, "map"),
                    pose: Pose::planar(k as f64, 0.0, 0.1),
                },
            )
            .unwrap();
        }
        let yaml = w.finish().unwrap();
        assert!(yaml.contains("message_count: 10"), "{yaml}");
        assert!(yaml.contains("nanoseconds: 40000000"), "{yaml}");
        path
    }

    #[test]
    fn written_bag_reads_back_with_stored_definitions() {
        let dir = tempfile::tempdir().unwrap();
        let path = write_bag(dir.path());
        let bag = Bag::open(dir.path()).unwrap();
        assert_eq!(bag.topics().len(), 2);
        assert_eq!(bag.topic("/joint_states").unwrap().message_count, 5);
        let schema = bag.schema("/joint_states").unwrap();
        let p = schema.path("position").unwrap();
        let mut seen = Vec::new();
        let n = bag
            .for_each("/joint_states", |m| {
                let pos = m.value.at(&p).unwrap().as_array().unwrap();
                seen.push(pos[1].as_f64().unwrap());
                Ok(())
            })
            .unwrap();
        assert_eq!(n, 5);
        assert_eq!(seen, vec![0.0, -1.0, -2.0, -3.0, -4.0]);

        let e = Bag::open(&path)
            .unwrap()
            .for_each("/pose", |m| {
                if m.index == 3 {
                    Err("no good".into())
                } else {
                    Ok(())
                }
            })
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("topic `/pose`, message 3") && e.contains("no good"),
            "{e}"
        );
        let e = bag.schema("/odom").unwrap_err().to_string();
        assert!(
            e.contains("not in the bag")
                && e.contains("/pose (geometry_msgs/msg/PoseStamped, 5 messages)"),
            "{e}"
        );
    }
}
