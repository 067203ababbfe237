//! The sqlite3 side of [`super::BagWriter`]: the tables rosbag2's sqlite3
//! plugin creates for the distribution, so that distribution's
//! `ros2 bag play` reads the file without the MCAP plugin.
//!
//! | distribution | `schema_version` | tables |
//! |---|---|---|
//! | Humble | 3 | `schema`, `metadata`, `topics` (with `offered_qos_profiles`), `messages` |
//! | Jazzy | 4 | those, `topics.type_description_hash`, `message_definitions` |
//!
//! Everything is written in one transaction; the file is complete (and
//! synced) when [`StorageWrite::finish`] returns.

use std::path::Path;

use rusqlite::Connection;

use super::storage_write::{StorageWrite, TopicSpec, WriteError};
use crate::msgs::Distro;

pub(super) struct SqliteStorage {
    conn: Connection,
    distro: Distro,
    /// Types already in `message_definitions`.
    defined: Vec<&'static str>,
}

const TABLES: &str = "
CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);
CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL, metadata TEXT NOT NULL);
CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, data BLOB NOT NULL);
CREATE INDEX timestamp_idx ON messages (timestamp ASC);
";
const TOPICS_HUMBLE: &str = "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, \
serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);";
const TOPICS_JAZZY: &str = "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, \
serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL, type_description_hash TEXT NOT NULL);
CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL, encoding TEXT NOT NULL, \
encoded_message_definition TEXT NOT NULL, type_description_hash TEXT NOT NULL);";

impl SqliteStorage {
    pub fn create(path: &Path, distro: Distro) -> Result<Self, WriteError> {
        if path.exists() {
            return Err(WriteError::Io(std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                format!("{} exists", path.display()),
            )));
        }
        let conn = Connection::open(path)?;
        conn.execute_batch("PRAGMA journal_mode = MEMORY; PRAGMA synchronous = FULL; BEGIN;")?;
        conn.execute_batch(TABLES)?;
        let (version, topics) = match distro {
            Distro::Humble => (3, TOPICS_HUMBLE),
            Distro::Jazzy => (4, TOPICS_JAZZY),
        };
        conn.execute_batch(topics)?;
        conn.execute(
            "INSERT INTO schema(schema_version, ros_distro) VALUES (?1, ?2)",
            rusqlite::params![version, distro.name()],
        )?;
        Ok(Self {
            conn,
            distro,
            defined: Vec::new(),
        })
    }
}

impl StorageWrite for SqliteStorage {
    fn add_topic(&mut self, index: usize, t: &TopicSpec<'_>) -> Result<(), WriteError> {
        // rosbag2 numbers topics from 1.
        let id = index as i64 + 1;
        match self.distro {
            Distro::Humble => {
                self.conn.execute(
                    "INSERT INTO topics VALUES (?1, ?2, ?3, 'cdr', ?4)",
                    rusqlite::params![id, t.name, t.type_name, t.qos.yaml()],
                )?;
            }
            Distro::Jazzy => {
                self.conn.execute(
                    "INSERT INTO topics VALUES (?1, ?2, ?3, 'cdr', ?4, ?5)",
                    rusqlite::params![id, t.name, t.type_name, t.qos.yaml(), t.type_hash],
                )?;
                if !self.defined.contains(&t.type_name) {
                    self.conn.execute(
                        "INSERT INTO message_definitions (topic_type, encoding, encoded_message_definition, type_description_hash) \
                         VALUES (?1, 'ros2msg', ?2, ?3)",
                        rusqlite::params![t.type_name, t.definition, t.type_hash],
                    )?;
                    self.defined.push(t.type_name);
                }
            }
        }
        Ok(())
    }

    fn write(
        &mut self,
        index: usize,
        _sequence: u64,
        t_ns: u64,
        data: &[u8],
    ) -> Result<(), WriteError> {
        let mut st = self.conn.prepare_cached(
            "INSERT INTO messages (topic_id, timestamp, data) VALUES (?1, ?2, ?3)",
        )?;
        st.execute(rusqlite::params![index as i64 + 1, t_ns as i64, data])?;
        Ok(())
    }

    fn finish(self: Box<Self>, metadata_yaml: &str) -> Result<(), WriteError> {
        self.conn.execute(
            "INSERT INTO metadata (metadata_version, metadata) VALUES (8, ?1)",
            [metadata_yaml],
        )?;
        self.conn.execute_batch("COMMIT;")?;
        self.conn.close().map_err(|(_, e)| e)?;
        Ok(())
    }
}
