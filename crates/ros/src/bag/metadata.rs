//! rosbag2's `metadata.yaml`: read in every layout rosbag2 has written
//! (versions 1 to 9: Foxy and Galactic write 4, Humble 5, Iron 7, Jazzy 9),
//! and written at version 8.
//!
//! What changed between versions (rosbag2's `yaml.hpp`): 3 added the
//! compression fields; 4 the topics' `offered_qos_profiles` (a YAML text);
//! 5 the per-file `files` list; 6 `custom_data`; 7 the topics'
//! `type_description_hash`; 8 `ros_distro`; 9 writes `offered_qos_profiles`
//! as a YAML list instead of a text. Fields a version does not have are
//! read as absent, never guessed.

use std::path::Path;

use serde_yaml_ng::Value as Yaml;

use super::BagError;
use crate::qos::Qos;

/// A topic as `metadata.yaml` lists it.
#[derive(Debug, Clone, PartialEq)]
pub struct MetadataTopic {
    pub name: String,
    pub type_name: String,
    pub serialization_format: String,
    pub message_count: u64,
}

/// A storage file as `metadata.yaml` lists it (version 5 on).
#[derive(Debug, Clone, PartialEq)]
pub struct MetadataFile {
    pub path: String,
    pub starting_time_ns: u64,
    pub duration_ns: u64,
    pub message_count: u64,
}

/// What twindrive uses of `metadata.yaml`.
#[derive(Debug, Clone, PartialEq)]
pub struct Metadata {
    pub version: u64,
    /// `sqlite3` or `mcap`.
    pub storage_identifier: String,
    /// The storage files in order, as written (older versions include the
    /// bag directory's name; only the file name is used).
    pub relative_file_paths: Vec<String>,
    pub files: Vec<MetadataFile>,
    pub topics: Vec<MetadataTopic>,
    pub starting_time_ns: u64,
    pub duration_ns: u64,
    pub message_count: u64,
    /// `""`, `zstd`.
    pub compression_format: String,
    /// `""`/`NONE`, `FILE` or `MESSAGE` (any case).
    pub compression_mode: String,
    pub ros_distro: Option<String>,
}

/// The highest version read; rosbag2 writes no higher yet.
pub const NEWEST_VERSION: u64 = 9;

impl Metadata {
    /// Reads `path` (a `metadata.yaml`).
    pub fn read(path: &Path) -> Result<Self, BagError> {
        let text = std::fs::read_to_string(path).map_err(|e| BagError::Io {
            path: path.into(),
            source: e,
        })?;
        Self::parse(&text).map_err(|message| BagError::File {
            path: path.into(),
            message,
        })
    }

    /// Parses the text of a `metadata.yaml`; the error names the field.
    pub fn parse(text: &str) -> Result<Self, String> {
        let doc: Yaml =
            serde_yaml_ng::from_str(text).map_err(|e| format!("not valid YAML: {e}"))?;
        let root = doc
            .get("rosbag2_bagfile_information")
            .ok_or("no `rosbag2_bagfile_information` mapping (not a rosbag2 metadata file)")?;
        let at = Fields {
            node: root,
            path: "rosbag2_bagfile_information".into(),
        };
        let version = at.u64("version")?;
        if version > NEWEST_VERSION {
            return Err(format!(
                "rosbag2_bagfile_information.version: {version}, and twindrive reads versions 1 to {NEWEST_VERSION}"
            ));
        }
        let topics = at
            .seq("topics_with_message_count")?
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let entry = Fields {
                    node: t,
                    path: format!("{}.topics_with_message_count[{i}]", at.path),
                };
                let meta = entry.child("topic_metadata")?;
                Ok(MetadataTopic {
                    name: meta.str("name")?,
                    type_name: meta.str("type")?,
                    serialization_format: meta.str("serialization_format")?,
                    message_count: entry.u64("message_count")?,
                })
            })
            .collect::<Result<Vec<_>, String>>()?;
        let files = if version >= 5 {
            at.seq("files")?
                .iter()
                .enumerate()
                .map(|(i, f)| {
                    let f = Fields {
                        node: f,
                        path: format!("{}.files[{i}]", at.path),
                    };
                    Ok(MetadataFile {
                        path: f.str("path")?,
                        starting_time_ns: f
                            .child("starting_time")?
                            .u64("nanoseconds_since_epoch")?,
                        duration_ns: f.child("duration")?.u64("nanoseconds")?,
                        message_count: f.u64("message_count")?,
                    })
                })
                .collect::<Result<Vec<_>, String>>()?
        } else {
            Vec::new()
        };
        let (compression_format, compression_mode) = if version >= 3 {
            (
                at.opt_str("compression_format")?.unwrap_or_default(),
                at.opt_str("compression_mode")?.unwrap_or_default(),
            )
        } else {
            Default::default()
        };
        Ok(Self {
            version,
            storage_identifier: at.str("storage_identifier")?,
            relative_file_paths: at
                .seq("relative_file_paths")?
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    p.as_str().map(str::to_string).ok_or_else(|| {
                        format!("{}.relative_file_paths[{i}]: expected a path", at.path)
                    })
                })
                .collect::<Result<_, _>>()?,
            files,
            topics,
            starting_time_ns: at.child("starting_time")?.u64("nanoseconds_since_epoch")?,
            duration_ns: at.child("duration")?.u64("nanoseconds")?,
            message_count: at.u64("message_count")?,
            compression_format,
            compression_mode,
            ros_distro: if version >= 8 {
                at.opt_str("ros_distro")?
            } else {
                None
            },
        })
    }

    /// Whether each message's bytes are compressed on their own.
    pub fn compresses_messages(&self) -> bool {
        self.compression_mode.eq_ignore_ascii_case("message")
    }
}

/// A mapping and where it is, for errors that name the field.
struct Fields<'a> {
    node: &'a Yaml,
    path: String,
}

impl<'a> Fields<'a> {
    fn get(&self, key: &str) -> Result<&'a Yaml, String> {
        self.node
            .get(key)
            .ok_or_else(|| format!("{}.{key}: missing", self.path))
    }

    fn child(&self, key: &str) -> Result<Fields<'a>, String> {
        Ok(Fields {
            node: self.get(key)?,
            path: format!("{}.{key}", self.path),
        })
    }

    fn u64(&self, key: &str) -> Result<u64, String> {
        let v = self.get(key)?;
        v.as_u64().ok_or_else(|| {
            format!(
                "{}.{key}: expected a whole number >= 0, got {v:?}",
                self.path
            )
        })
    }

    fn str(&self, key: &str) -> Result<String, String> {
        self.opt_str(key)?
            .ok_or_else(|| format!("{}.{key}: missing", self.path))
    }

    /// A text field; absent or `~` is `None`.
    fn opt_str(&self, key: &str) -> Result<Option<String>, String> {
        match self.node.get(key) {
            None | Some(Yaml::Null) => Ok(None),
            Some(Yaml::String(s)) => Ok(Some(s.clone())),
            Some(v) => Err(format!("{}.{key}: expected text, got {v:?}", self.path)),
        }
    }

    fn seq(&self, key: &str) -> Result<&'a [Yaml], String> {
        match self.node.get(key) {
            None | Some(Yaml::Null) => Ok(&[]),
            Some(Yaml::Sequence(s)) => Ok(s),
            Some(v) => Err(format!("{}.{key}: expected a list, got {v:?}", self.path)),
        }
    }
}

/// A topic for [`render`].
pub struct RenderTopic<'a> {
    pub name: &'a str,
    pub type_name: &'a str,
    pub qos: Qos,
    /// RIHS01, or empty (Humble).
    pub type_hash: &'a str,
    pub message_count: u64,
}

/// `metadata.yaml` (version 8) of a bag of one storage file.
pub fn render(
    storage_identifier: &str,
    file_name: &str,
    topics: &[RenderTopic<'_>],
    time_range_ns: Option<(u64, u64)>,
    ros_distro: &str,
) -> String {
    use std::fmt::Write as _;
    let (start, end) = time_range_ns.unwrap_or((0, 0));
    let duration = end - start;
    let total: u64 = topics.iter().map(|t| t.message_count).sum();
    let quote = |s: &str| serde_json::to_string(s).expect("a string");
    let mut y = String::new();
    let _ = writeln!(y, "rosbag2_bagfile_information:");
    let _ = writeln!(y, "  version: 8");
    let _ = writeln!(y, "  storage_identifier: {storage_identifier}");
    let _ = writeln!(y, "  duration:\n    nanoseconds: {duration}");
    let _ = writeln!(y, "  starting_time:\n    nanoseconds_since_epoch: {start}");
    let _ = writeln!(y, "  message_count: {total}");
    let _ = writeln!(y, "  topics_with_message_count:");
    for t in topics {
        let _ = writeln!(y, "    - topic_metadata:");
        let _ = writeln!(y, "        name: {}", quote(t.name));
        let _ = writeln!(y, "        type: {}", t.type_name);
        let _ = writeln!(y, "        serialization_format: cdr");
        let _ = writeln!(y, "        offered_qos_profiles: {}", quote(&t.qos.yaml()));
        let _ = writeln!(y, "        type_description_hash: {}", quote(t.type_hash));
        let _ = writeln!(y, "      message_count: {}", t.message_count);
    }
    let _ = writeln!(y, "  compression_format: \"\"");
    let _ = writeln!(y, "  compression_mode: \"\"");
    let _ = writeln!(y, "  relative_file_paths:\n    - {}", quote(file_name));
    let _ = writeln!(y, "  files:");
    let _ = writeln!(y, "    - path: {}", quote(file_name));
    let _ = writeln!(
        y,
        "      starting_time:\n        nanoseconds_since_epoch: {start}"
    );
    let _ = writeln!(y, "      duration:\n        nanoseconds: {duration}");
    let _ = writeln!(y, "      message_count: {total}");
    let _ = writeln!(y, "  custom_data: ~");
    let _ = writeln!(y, "  ros_distro: {ros_distro}");
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What Foxy's rosbag2 writes (version 4: QoS as text, no `files`).
    const FOXY: &str = r#"
rosbag2_bagfile_information:
  version: 4
  storage_identifier: sqlite3
  relative_file_paths:
    - rosbag2_2021_01_01-00_00_00_0.db3
  duration:
    nanoseconds: 2000000000
  starting_time:
    nanoseconds_since_epoch: 1609459200000000000
  message_count: 3
  topics_with_message_count:
    - topic_metadata:
        name: /chatter
        type: std_msgs/msg/String
        serialization_format: cdr
        offered_qos_profiles: "- history: 3\n  depth: 0\n  reliability: 1\n"
      message_count: 3
  compression_format: ""
  compression_mode: ""
"#;

    #[test]
    fn reads_foxy_and_names_missing_fields() {
        let m = Metadata::parse(FOXY).unwrap();
        assert_eq!(m.version, 4);
        assert_eq!(m.storage_identifier, "sqlite3");
        assert_eq!(m.topics[0].type_name, "std_msgs/msg/String");
        assert_eq!(m.topics[0].message_count, 3);
        assert!(m.files.is_empty() && m.ros_distro.is_none());
        let e = Metadata::parse(&FOXY.replace("  storage_identifier: sqlite3\n", "")).unwrap_err();
        assert_eq!(e, "rosbag2_bagfile_information.storage_identifier: missing");
        let e = Metadata::parse(&FOXY.replace(
            "message_count: 3\n  compression",
            "message_count: -3\n  compression",
        ))
        .unwrap_err();
        assert!(e.starts_with("rosbag2_bagfile_information.topics_with_message_count[0].message_count: expected a whole number"), "{e}");
        let e = Metadata::parse(&FOXY.replace("version: 4", "version: 10")).unwrap_err();
        assert!(e.contains("versions 1 to 9"), "{e}");
    }

    /// Versions before Foxy: 2 has no compression fields and no QoS, 3
    /// adds compression.
    #[test]
    fn reads_the_oldest_layouts() {
        let v2 = FOXY
            .replace("version: 4", "version: 2")
            .replace("        offered_qos_profiles: \"- history: 3\\n  depth: 0\\n  reliability: 1\\n\"\n", "")
            .replace("  compression_format: \"\"\n  compression_mode: \"\"\n", "");
        assert!(
            !v2.contains("offered_qos") && !v2.contains("compression"),
            "{v2}"
        );
        let m = Metadata::parse(&v2).unwrap();
        assert_eq!((m.version, m.compression_mode.as_str()), (2, ""));
        assert_eq!(m.topics[0].message_count, 3);
        let v3 = FOXY
            .replace("version: 4", "version: 3")
            .replace("compression_mode: \"\"", "compression_mode: FILE");
        let m = Metadata::parse(&v3).unwrap();
        assert_eq!(m.compression_mode, "FILE");
        assert!(!m.compresses_messages());
    }

    #[test]
    fn rendered_metadata_reads_back() {
        let topics = [RenderTopic {
            name: "/odom",
            type_name: "nav_msgs/msg/Odometry",
            qos: Qos::DEFAULT,
            type_hash: "",
            message_count: 7,
        }];
        let m = Metadata::parse(&render(
            "sqlite3",
            "b_0.db3",
            &topics,
            Some((5, 9)),
            "humble",
        ))
        .unwrap();
        assert_eq!(m.version, 8);
        assert_eq!(m.relative_file_paths, ["b_0.db3"]);
        assert_eq!(
            m.files,
            [MetadataFile {
                path: "b_0.db3".into(),
                starting_time_ns: 5,
                duration_ns: 4,
                message_count: 7
            }]
        );
        assert_eq!(m.ros_distro.as_deref(), Some("humble"));
    }
}
