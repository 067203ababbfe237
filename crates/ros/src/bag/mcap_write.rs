//! The MCAP side of [`super::BagWriter`]: zstd chunks, one schema per type,
//! the offered QoS (and the type hash from Jazzy on) in each channel's
//! metadata, and rosbag2's metadata record at the end.

use std::collections::BTreeMap;
use std::io::{Seek, Write};

use super::storage_write::{StorageWrite, TopicSpec, WriteError};
use crate::msgs::Distro;

pub(super) struct McapStorage<W: Write + Seek> {
    mcap: mcap::Writer<W>,
    distro: Distro,
    /// Schema id per type.
    schemas: BTreeMap<&'static str, u16>,
    /// Channel id per topic index.
    channels: Vec<u16>,
}

impl<W: Write + Seek> McapStorage<W> {
    pub fn new(w: W, distro: Distro) -> Result<Self, WriteError> {
        let mcap = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("twindrive-ros ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .create(w)?;
        Ok(Self {
            mcap,
            distro,
            schemas: BTreeMap::new(),
            channels: Vec::new(),
        })
    }
}

impl<W: Write + Seek> StorageWrite for McapStorage<W> {
    fn add_topic(&mut self, index: usize, t: &TopicSpec<'_>) -> Result<(), WriteError> {
        debug_assert_eq!(index, self.channels.len());
        let schema = match self.schemas.get(t.type_name) {
            Some(id) => *id,
            None => {
                let id = self
                    .mcap
                    .add_schema(t.type_name, "ros2msg", t.definition.as_bytes())?;
                self.schemas.insert(t.type_name, id);
                id
            }
        };
        let mut meta = BTreeMap::new();
        meta.insert("offered_qos_profiles".to_string(), t.qos.yaml());
        if !t.type_hash.is_empty() {
            meta.insert("topic_type_hash".to_string(), t.type_hash.to_string());
        }
        let channel = self.mcap.add_channel(schema, t.name, "cdr", &meta)?;
        self.channels.push(channel);
        Ok(())
    }

    fn write(
        &mut self,
        index: usize,
        sequence: u64,
        t_ns: u64,
        data: &[u8],
    ) -> Result<(), WriteError> {
        self.mcap.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: self.channels[index],
                sequence: sequence as u32,
                log_time: t_ns,
                publish_time: t_ns,
            },
            data,
        )?;
        Ok(())
    }

    fn finish(mut self: Box<Self>, metadata_yaml: &str) -> Result<(), WriteError> {
        let mut meta = BTreeMap::new();
        meta.insert("serialized_metadata".to_string(), metadata_yaml.to_string());
        meta.insert("ROS_DISTRO".to_string(), self.distro.name().to_string());
        self.mcap.write_metadata(&mcap::records::Metadata {
            name: "rosbag2".into(),
            metadata: meta,
        })?;
        self.mcap.finish()?;
        Ok(())
    }
}
