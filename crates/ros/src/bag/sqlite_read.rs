//! Reading one sqlite3 storage file (`.db3`) through SQLite itself
//! (`rusqlite`, bundled): every table layout rosbag2 has written, from
//! Foxy's (`topics`, `messages`) through Humble's (`schema`, `metadata`) to
//! Iron's on (`message_definitions`, `type_description_hash`). Messages are
//! read in the order they were written (row id); a database cut short or
//! damaged is read up to the first row SQLite cannot read.

use std::collections::HashMap;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rusqlite::{Connection, OpenFlags};

use super::source::Source;
use super::{BagError, Damage, FileScan, RawVisitor, StoredDefinition, StoredTopic, TopicFilter};

/// A temporary copy of a database, removed when dropped.
#[derive(Debug)]
enum TempCopy {
    File { _path: tempfile::TempPath },
    Dir { _dir: tempfile::TempDir },
}

/// A database ready to open: the file itself, or its decompressed copy.
#[derive(Debug, Clone)]
pub(super) struct Db {
    path: PathBuf,
    /// A copy made to read it (removed on drop).
    _copy: Option<Arc<TempCopy>>,
    /// How the file falls short (a compressed stream cut short, fewer
    /// pages than the header says).
    pub shortfall: Option<String>,
}

impl Db {
    /// `source` as SQLite can open it: a compressed file is decompressed
    /// into a temporary file first (SQLite needs random access), and a
    /// file shorter than its header says (cut short) is copied with the
    /// header's page count set to the pages present, so SQLite reads what
    /// is there instead of refusing the whole file.
    pub fn prepare(source: &Source) -> Result<Self, BagError> {
        let io = |e: std::io::Error| BagError::Io {
            path: source.path.clone(),
            source: e,
        };
        let wal = PathBuf::from(format!("{}-wal", source.path.display()));
        if !source.compressed() && wal.metadata().is_ok_and(|m| m.len() > 0) {
            return Self::with_wal(source, &wal);
        }
        if !source.compressed() {
            let header = read_header(&source.path).map_err(io)?;
            let len = source.len();
            if header.is_none_or(|h| h.whole_len() <= len) {
                return Ok(Self {
                    path: source.path.clone(),
                    _copy: None,
                    shortfall: None,
                });
            }
        }
        let mut copy = tempfile::Builder::new()
            .prefix("twindrive-bag-")
            .suffix(".db3")
            .tempfile()
            .map_err(|e| temp_error(source, e))?;
        let mut input = source.stream()?;
        let mut buf = vec![0u8; 1 << 16];
        let mut shortfall = None;
        loop {
            match input.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => copy
                    .write_all(&buf[..n])
                    .map_err(|e| temp_error(source, e))?,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    shortfall = Some(format!("the zstd stream stops short ({e})"));
                    break;
                }
            }
        }
        copy.flush().map_err(io)?;
        let len = copy.as_file().metadata().map_err(io)?.len();
        let header = read_header(copy.path()).map_err(io)?;
        if let Some(why) = &shortfall
            && header.is_none()
        {
            return Err(BagError::File {
                path: source.path.clone(),
                message: format!("no whole message can be read: {why}"),
            });
        }
        if let Some(h) = header
            && h.whole_len() > len
        {
            let pages = (len / h.page_size) as u32;
            shortfall.get_or_insert(format!(
                "the file holds {len} bytes of the {} its header promises",
                h.whole_len()
            ));
            copy.as_file()
                .set_len(pages as u64 * h.page_size)
                .map_err(io)?;
            copy.seek(SeekFrom::Start(28)).map_err(io)?;
            copy.write_all(&pages.to_be_bytes()).map_err(io)?;
            copy.flush().map_err(io)?;
        }
        Ok(Self {
            path: copy.path().to_path_buf(),
            _copy: Some(Arc::new(TempCopy::File {
                _path: copy.into_temp_path(),
            })),
            shortfall,
        })
    }

    /// A recording that did not close (rosbag2's `resilient` preset writes
    /// ahead): its last messages are in the `-wal` file beside it. Both are
    /// copied into a temporary directory and the log is folded in there,
    /// so the user's files stay as they are.
    fn with_wal(source: &Source, wal: &Path) -> Result<Self, BagError> {
        let dir = tempfile::Builder::new()
            .prefix("twindrive-bag-")
            .tempdir()
            .map_err(|e| temp_error(source, e))?;
        let db = dir.path().join("bag.db3");
        std::fs::copy(&source.path, &db).map_err(|e| temp_error(source, e))?;
        std::fs::copy(wal, dir.path().join("bag.db3-wal")).map_err(|e| temp_error(source, e))?;
        let conn = Connection::open(&db).map_err(|e| BagError::File {
            path: source.path.clone(),
            message: format!("SQLite cannot open it with its write-ahead log: {e}"),
        })?;
        conn.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))
            .map_err(|e| BagError::File {
                path: source.path.clone(),
                message: format!("folding in its write-ahead log: {e}"),
            })?;
        drop(conn);
        let _ = std::fs::remove_file(dir.path().join("bag.db3-wal"));
        let _ = std::fs::remove_file(dir.path().join("bag.db3-shm"));
        let path = dir.path().join("bag.db3");
        Ok(Self {
            path,
            _copy: Some(Arc::new(TempCopy::Dir { _dir: dir })),
            shortfall: None,
        })
    }

    fn connect(&self, shown: &Path) -> Result<Connection, BagError> {
        // Opened read-only and immutable: no locks, no journal, nothing
        // written beside the file (it may sit on a read-only disk, or in a
        // repository).
        let uri = format!("file:{}?immutable=1", uri_path(&self.path));
        let err = |e: rusqlite::Error| BagError::File {
            path: shown.into(),
            message: format!("SQLite cannot open it: {e}"),
        };
        Connection::open_with_flags(
            uri,
            OpenFlags::SQLITE_OPEN_READ_ONLY
                | OpenFlags::SQLITE_OPEN_URI
                | OpenFlags::SQLITE_OPEN_NO_MUTEX,
        )
        .map_err(err)
    }
}

/// Making the working copy failed: the error names where copies go.
fn temp_error(source: &Source, e: std::io::Error) -> BagError {
    BagError::File {
        path: source.path.clone(),
        message: format!(
            "a working copy in {} (set TMPDIR to another directory): {e}",
            std::env::temp_dir().display()
        ),
    }
}

/// What the first 100 bytes of an SQLite file say about its size.
struct Header {
    page_size: u64,
    pages: u64,
}

impl Header {
    fn whole_len(&self) -> u64 {
        self.page_size * self.pages
    }
}

/// The page size and page count of an SQLite file (`None` when it has no
/// whole header, or the count is not in use).
fn read_header(path: &Path) -> std::io::Result<Option<Header>> {
    let mut head = [0u8; 100];
    let mut f = std::fs::File::open(path)?;
    if f.read_exact(&mut head).is_err() {
        return Ok(None);
    }
    let page_size = match u16::from_be_bytes([head[16], head[17]]) {
        1 => 65536,
        n => n as u64,
    };
    let pages = u32::from_be_bytes([head[28], head[29], head[30], head[31]]) as u64;
    // The count is valid only when the change counter matches the
    // version-valid-for number (SQLite file format, section 1.3.7).
    let valid = head[24..28] == head[92..96];
    Ok((valid && pages > 0 && page_size >= 512).then_some(Header { page_size, pages }))
}

/// `path` for a SQLite `file:` URI: `%`, `?` and `#` escaped.
fn uri_path(path: &Path) -> String {
    let mut out = String::new();
    for c in path.to_string_lossy().chars() {
        match c {
            '%' | '?' | '#' => out.push_str(&format!("%{:02X}", c as u32)),
            c => out.push(c),
        }
    }
    out
}

fn has_table(conn: &Connection, name: &str) -> rusqlite::Result<bool> {
    conn.query_row(
        "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = ?1",
        [name],
        |r| r.get::<_, i64>(0),
    )
    .map(|n| n > 0)
}

/// Reads the topics, the definitions and every message once.
pub(super) fn scan(source: &Source, db: &Db) -> Result<FileScan, BagError> {
    let conn = db.connect(&source.path)?;
    let bad = |what: &str, e: rusqlite::Error| BagError::File {
        path: source.path.clone(),
        message: format!("not a readable rosbag2 sqlite3 file ({what}: {e})"),
    };
    if !has_table(&conn, "topics").map_err(|e| bad("its table list", e))?
        || !has_table(&conn, "messages").map_err(|e| bad("its table list", e))?
    {
        return Err(BagError::File {
            path: source.path.clone(),
            message: "an SQLite database without rosbag2's `topics` and `messages` tables".into(),
        });
    }
    let mut scan = FileScan::default();
    if has_table(&conn, "schema").map_err(|e| bad("its table list", e))? {
        scan.ros_distro = conn
            .query_row("SELECT ros_distro FROM schema", [], |r| r.get(0))
            .ok();
    }
    if has_table(&conn, "message_definitions").map_err(|e| bad("its table list", e))? {
        let mut st = conn
            .prepare(
                "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions ORDER BY id",
            )
            .map_err(|e| bad("message_definitions", e))?;
        let rows = st
            .query_map([], |r| {
                Ok(StoredDefinition {
                    type_name: r.get(0)?,
                    encoding: r.get(1)?,
                    data: r.get::<_, String>(2)?.into_bytes(),
                })
            })
            .map_err(|e| bad("message_definitions", e))?;
        for d in rows {
            scan.definitions
                .push(d.map_err(|e| bad("message_definitions", e))?);
        }
    }
    let mut ids: HashMap<i64, usize> = HashMap::new();
    {
        let mut st = conn
            .prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id")
            .map_err(|e| bad("topics", e))?;
        let rows = st
            .query_map([], |r| {
                Ok((
                    r.get::<_, i64>(0)?,
                    r.get::<_, String>(1)?,
                    r.get::<_, String>(2)?,
                    r.get::<_, String>(3)?,
                ))
            })
            .map_err(|e| bad("topics", e))?;
        for row in rows {
            let (id, name, type_name, format) = row.map_err(|e| bad("topics", e))?;
            ids.insert(id, scan.topics.len());
            scan.topics.push(StoredTopic {
                name,
                type_name,
                serialization_format: format,
                definition_encoding: String::new(),
                message_count: 0,
            });
        }
    }
    let mut st = conn
        .prepare("SELECT id, topic_id, timestamp, data FROM messages ORDER BY id")
        .map_err(|e| bad("messages", e))?;
    let mut rows = st.query([]).map_err(|e| bad("messages", e))?;
    loop {
        let row = match rows.next() {
            Ok(Some(row)) => row,
            Ok(None) => break,
            Err(e) => {
                scan.damage = Some(damage(source, db, &scan, e.to_string()));
                break;
            }
        };
        let read = (|| {
            let id: i64 = row.get(0)?;
            let topic: i64 = row.get(1)?;
            let t: i64 = row.get(2)?;
            let _ = row.get_ref(3)?.as_blob()?;
            Ok::<_, rusqlite::Error>((id, topic, t))
        })();
        match read {
            Ok((id, topic, t)) => {
                scan.last_row_id = id;
                let Some(&k) = ids.get(&topic) else {
                    return Err(BagError::File {
                        path: source.path.clone(),
                        message: format!(
                            "message {} is on topic id {topic}, which the `topics` table does not list",
                            scan.messages
                        ),
                    });
                };
                scan.topics[k].message_count += 1;
                scan.add_message(t.max(0) as u64);
            }
            Err(e) => {
                scan.damage = Some(damage(source, db, &scan, e.to_string()));
                break;
            }
        }
    }
    if scan.damage.is_none() && db.shortfall.is_some() {
        scan.damage = Some(damage(source, db, &scan, "the last rows are gone".into()));
    }
    Ok(scan)
}

fn damage(source: &Source, db: &Db, scan: &FileScan, reason: String) -> Damage {
    Damage {
        path: source.path.clone(),
        messages_read: scan.messages,
        time_range_ns: scan.time_range_ns(),
        position: format!(
            "the `messages` table up to row {}{}",
            scan.last_row_id,
            db.shortfall
                .as_ref()
                .map(|s| format!("; {s}"))
                .unwrap_or_default()
        ),
        reason: format!("SQLite stops reading: {reason}"),
    }
}

/// Hands `f` the messages up to row `last_row_id` (where the scan stopped)
/// in the order they were written, with the position `want` gives their
/// topic (asked once per topic).
pub(super) fn read(
    source: &Source,
    db: &Db,
    last_row_id: i64,
    want: &mut TopicFilter<'_>,
    f: &mut RawVisitor<'_>,
) -> Result<(), BagError> {
    let conn = db.connect(&source.path)?;
    let bad = |e: rusqlite::Error| BagError::File {
        path: source.path.clone(),
        message: format!("reading messages: {e}"),
    };
    let mut wanted: HashMap<i64, Option<usize>> = HashMap::new();
    {
        let mut st = conn.prepare("SELECT id, name FROM topics").map_err(bad)?;
        let rows = st
            .query_map([], |r| Ok((r.get::<_, i64>(0)?, r.get::<_, String>(1)?)))
            .map_err(bad)?;
        for row in rows {
            let (id, name) = row.map_err(bad)?;
            wanted.insert(id, want(&name));
        }
    }
    let ids: Vec<String> = wanted
        .iter()
        .filter(|(_, k)| k.is_some())
        .map(|(id, _)| id.to_string())
        .collect();
    if ids.is_empty() {
        return Ok(());
    }
    // Other topics' data is not read. The loop stops at the scan's last
    // row: asking for one more would step onto the damage.
    let mut st = conn
        .prepare(&format!(
            "SELECT id, topic_id, timestamp, CASE WHEN topic_id IN ({}) THEN data END FROM messages WHERE id <= ?1 ORDER BY id",
            ids.join(", ")
        ))
        .map_err(bad)?;
    let mut rows = st.query([last_row_id]).map_err(bad)?;
    while let Some(row) = rows.next().map_err(bad)? {
        let id: i64 = row.get(0).map_err(bad)?;
        let topic: i64 = row.get(1).map_err(bad)?;
        if let Some(Some(k)) = wanted.get(&topic) {
            let t: i64 = row.get(2).map_err(bad)?;
            let data = row
                .get_ref(3)
                .map_err(bad)?
                .as_blob()
                .map_err(|e| bad(e.into()))?;
            f(*k, t.max(0) as u64, data)?;
        }
        if id >= last_row_id {
            break;
        }
    }
    Ok(())
}
