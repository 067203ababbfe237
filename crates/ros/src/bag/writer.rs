//! Writing a rosbag2 bag of one storage file, in either storage: the
//! topics, their QoS and type hashes, the message counts and time range,
//! and the `metadata.yaml` text that goes beside the file.

use std::io::{Seek, Write};
use std::path::Path;

use super::metadata::{self, RenderTopic};
use super::storage_write::{StorageWrite, TopicSpec, WriteError};
use super::{mcap_write, sqlite_write};
use crate::msgs::{self, Distro, RosMessage};
use crate::qos::Qos;

/// A topic handle from [`BagWriter::topic`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicId(usize);

struct WrittenTopic {
    name: String,
    type_name: &'static str,
    type_hash: String,
    qos: Qos,
    count: u64,
}

/// Writes one storage file of a rosbag2 bag (profile `ros2`, definitions
/// `ros2msg`, messages `cdr`).
pub struct BagWriter<'w> {
    storage: Box<dyn StorageWrite + 'w>,
    identifier: &'static str,
    distro: Distro,
    file_name: String,
    topics: Vec<WrittenTopic>,
    time_range: Option<(u64, u64)>,
    buf: Vec<u8>,
}

impl<'w> BagWriter<'w> {
    /// An MCAP file (zstd chunks) written to `w`; `file_name` is how
    /// `metadata.yaml` refers to it.
    pub fn mcap<W: Write + Seek + 'w>(
        w: W,
        file_name: &str,
        distro: Distro,
    ) -> Result<Self, WriteError> {
        Ok(Self::with(
            Box::new(mcap_write::McapStorage::new(w, distro)?),
            "mcap",
            file_name,
            distro,
        ))
    }

    /// A sqlite3 database created at `path` (which must not exist), laid
    /// out as `distro`'s rosbag2 writes it; `file_name` is how
    /// `metadata.yaml` refers to it.
    pub fn sqlite3(path: &Path, file_name: &str, distro: Distro) -> Result<Self, WriteError> {
        Ok(Self::with(
            Box::new(sqlite_write::SqliteStorage::create(path, distro)?),
            "sqlite3",
            file_name,
            distro,
        ))
    }

    fn with(
        storage: Box<dyn StorageWrite + 'w>,
        identifier: &'static str,
        file_name: &str,
        distro: Distro,
    ) -> Self {
        Self {
            storage,
            identifier,
            distro,
            file_name: file_name.to_string(),
            topics: Vec::new(),
            time_range: None,
            buf: Vec::new(),
        }
    }

    /// The distribution whose definitions the bag follows.
    pub fn distro(&self) -> Distro {
        self.distro
    }

    /// Declares `name` with messages of type `T`.
    pub fn topic<T: RosMessage>(&mut self, name: &str, qos: Qos) -> Result<TopicId, WriteError> {
        let definition =
            msgs::definition(T::TYPE, self.distro).expect("every RosMessage has a definition");
        let type_hash = match self.distro {
            Distro::Humble => String::new(),
            Distro::Jazzy => msgs::type_hash(T::TYPE).expect("the built-in definitions parse"),
        };
        let index = self.topics.len();
        self.storage.add_topic(
            index,
            &TopicSpec {
                name,
                type_name: T::TYPE,
                definition: &definition,
                type_hash: &type_hash,
                qos,
            },
        )?;
        self.topics.push(WrittenTopic {
            name: name.to_string(),
            type_name: T::TYPE,
            type_hash,
            qos,
            count: 0,
        });
        Ok(TopicId(index))
    }

    /// Writes `msg` on `topic`, received (and published) at `t_ns`.
    pub fn write<T: RosMessage>(
        &mut self,
        topic: TopicId,
        t_ns: u64,
        msg: &T,
    ) -> Result<(), WriteError> {
        let t = &mut self.topics[topic.0];
        debug_assert_eq!(
            t.type_name,
            T::TYPE,
            "topic {} written with another type",
            t.name
        );
        msgs::encode_into(&mut self.buf, msg);
        self.storage.write(topic.0, t.count, t_ns, &self.buf)?;
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
    pub fn finish(self) -> Result<String, WriteError> {
        let topics: Vec<RenderTopic<'_>> = self
            .topics
            .iter()
            .map(|t| RenderTopic {
                name: &t.name,
                type_name: t.type_name,
                qos: t.qos,
                type_hash: &t.type_hash,
                message_count: t.count,
            })
            .collect();
        let yaml = metadata::render(
            self.identifier,
            &self.file_name,
            &topics,
            self.time_range,
            self.distro.name(),
        );
        self.storage.finish(&yaml)?;
        Ok(yaml)
    }
}
