//! The boundary between [`super::BagWriter`] and a storage: what a storage
//! is given (topics with their definitions, message bytes) and does (write
//! them, finish the file), and how writing fails.

use crate::qos::Qos;

/// Writing a bag failed.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error("writing MCAP: {0}")]
    Mcap(#[from] mcap::McapError),
    #[error("writing the sqlite3 database: {0}")]
    Sqlite(#[from] rusqlite::Error),
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// A topic as the storage writes it.
pub(super) struct TopicSpec<'a> {
    pub name: &'a str,
    pub type_name: &'static str,
    /// The full `ros2msg` definition.
    pub definition: &'a str,
    /// RIHS01, or empty (Humble).
    pub type_hash: &'a str,
    pub qos: Qos,
}

/// One storage's side of [`BagWriter`].
pub(super) trait StorageWrite {
    /// Declares topic number `index` (0, 1, … in order).
    fn add_topic(&mut self, index: usize, topic: &TopicSpec<'_>) -> Result<(), WriteError>;
    /// Writes the `sequence`-th message of topic `index`.
    fn write(
        &mut self,
        index: usize,
        sequence: u64,
        t_ns: u64,
        data: &[u8],
    ) -> Result<(), WriteError>;
    /// Completes the file; `metadata_yaml` is what goes beside it.
    fn finish(self: Box<Self>, metadata_yaml: &str) -> Result<(), WriteError>;
}
