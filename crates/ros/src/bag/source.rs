//! A storage file of a bag as it lies on disk: plain, or compressed whole
//! with zstd (rosbag2's `--compression-mode file`: `name_0.db3.zstd`,
//! `name_0.mcap.zstd`). A compressed file cut short decompresses up to the
//! damage, and the storage reader sees a file that ends there.

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use super::BagError;

/// rosbag2's two storages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Storage {
    Mcap,
    Sqlite3,
}

impl Storage {
    /// rosbag2's `storage_identifier`.
    pub fn identifier(self) -> &'static str {
        match self {
            Storage::Mcap => "mcap",
            Storage::Sqlite3 => "sqlite3",
        }
    }

    pub fn from_identifier(id: &str) -> Option<Self> {
        match id {
            "mcap" => Some(Storage::Mcap),
            "sqlite3" => Some(Storage::Sqlite3),
            _ => None,
        }
    }

    /// The storage whose magic bytes a file starts with.
    fn by_magic(head: &[u8]) -> Option<Self> {
        if head.starts_with(MCAP_MAGIC) {
            Some(Storage::Mcap)
        } else if head.starts_with(SQLITE_MAGIC) {
            Some(Storage::Sqlite3)
        } else {
            None
        }
    }

    /// The file extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            Storage::Mcap => "mcap",
            Storage::Sqlite3 => "db3",
        }
    }
}

const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";
const SQLITE_MAGIC: &[u8] = b"SQLite format 3\0";
const ZSTD_MAGIC: &[u8] = &[0x28, 0xb5, 0x2f, 0xfd];

/// One storage file.
#[derive(Debug, Clone)]
pub struct Source {
    pub path: PathBuf,
    pub storage: Storage,
    /// Compressed whole with zstd.
    compressed: bool,
}

impl Source {
    /// What `path` holds, by its name (`.mcap`, `.db3`, either with
    /// `.zstd`) or, for other names, by its first bytes. `None` for a file
    /// that is neither storage.
    pub fn recognise(path: &Path) -> Result<Option<Self>, BagError> {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let (stem, compressed) = match name.strip_suffix(".zstd") {
            Some(stem) => (stem.to_string(), true),
            None => (name.clone(), false),
        };
        let by_name = [Storage::Mcap, Storage::Sqlite3]
            .into_iter()
            .find(|s| stem.ends_with(&format!(".{}", s.extension())));
        if let Some(storage) = by_name {
            return Ok(Some(Self {
                path: path.into(),
                storage,
                compressed,
            }));
        }
        let mut head = [0u8; 16];
        let n = read_full(&mut open(path)?, &mut head).map_err(|e| io(path, e))?;
        let (storage, compressed) = match Storage::by_magic(&head[..n]) {
            Some(storage) => (storage, false),
            // A compressed file under another name: look inside.
            None if head[..n].starts_with(ZSTD_MAGIC) => {
                let mut d =
                    zstd::stream::read::Decoder::new(open(path)?).map_err(|e| io(path, e))?;
                let n = read_full(&mut d, &mut head).map_err(|e| io(path, e))?;
                match Storage::by_magic(&head[..n]) {
                    Some(storage) => (storage, true),
                    None => return Ok(None),
                }
            }
            None => return Ok(None),
        };
        Ok(Some(Self {
            path: path.into(),
            storage,
            compressed,
        }))
    }

    pub fn compressed(&self) -> bool {
        self.compressed
    }

    /// The file's bytes, decompressed when it is compressed. A compressed
    /// stream that is cut short fails at the cut, like a plain file that
    /// ends there.
    pub fn stream(&self) -> Result<Box<dyn Read>, BagError> {
        let file = open(&self.path)?;
        Ok(if self.compressed {
            Box::new(zstd::stream::read::Decoder::new(file).map_err(|e| io(&self.path, e))?)
        } else {
            Box::new(file)
        })
    }

    /// The file's size on disk.
    pub fn len(&self) -> u64 {
        std::fs::metadata(&self.path).map(|m| m.len()).unwrap_or(0)
    }
}

fn io(path: &Path, source: std::io::Error) -> BagError {
    BagError::Io {
        path: path.into(),
        source,
    }
}

fn open(path: &Path) -> Result<BufReader<File>, BagError> {
    Ok(BufReader::with_capacity(
        1 << 16,
        File::open(path).map_err(|e| io(path, e))?,
    ))
}

fn read_full(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// Decompresses `data` when it is a zstd frame (rosbag2's
/// `--compression-mode message`); CDR bytes never start with zstd's magic.
pub fn message_bytes(data: &[u8]) -> Result<std::borrow::Cow<'_, [u8]>, String> {
    if data.starts_with(ZSTD_MAGIC) {
        zstd::stream::decode_all(data)
            .map(Into::into)
            .map_err(|e| format!("the message is zstd-compressed and does not decompress: {e}"))
    } else {
        Ok(data.into())
    }
}
