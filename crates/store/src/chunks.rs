//! Upload chunks on disk.

use std::path::PathBuf;

use twindrive_link::upload::ChunkStore;
use twindrive_link::wire::Offer;

use twindrive_files::write_durably;

/// Chunks on disk: `DIR/<transfer hex>/<index>.chunk`, each written to a
/// temporary file, synced and renamed, so a chunk is either whole or absent.
#[derive(Debug, Clone)]
pub struct DirStore {
    dir: PathBuf,
}

impl DirStore {
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    fn transfer_dir(&self, offer: &Offer) -> PathBuf {
        self.dir.join(twindrive_plan::hex(&offer.transfer))
    }
}

impl ChunkStore for DirStore {
    fn open(&mut self, offer: &Offer) -> std::io::Result<Vec<bool>> {
        let dir = self.transfer_dir(offer);
        std::fs::create_dir_all(&dir)?;
        let offer_bytes = postcard::to_allocvec(offer).map_err(std::io::Error::other)?;
        write_durably(&dir.join("offer"), &offer_bytes)?;
        let mut have = vec![false; offer.chunks() as usize];
        for entry in std::fs::read_dir(&dir)? {
            let name = entry?.file_name().to_string_lossy().into_owned();
            if let Some(k) = name
                .strip_suffix(".chunk")
                .and_then(|k| k.parse::<usize>().ok())
                && k < have.len()
            {
                have[k] = true;
            }
        }
        Ok(have)
    }

    fn put(&mut self, offer: &Offer, index: u32, data: &[u8]) -> std::io::Result<()> {
        write_durably(
            &self.transfer_dir(offer).join(format!("{index}.chunk")),
            data,
        )
    }

    fn get(&mut self, offer: &Offer, index: u32) -> std::io::Result<Vec<u8>> {
        std::fs::read(self.transfer_dir(offer).join(format!("{index}.chunk")))
    }

    fn assemble(&mut self, offer: &Offer) -> std::io::Result<Vec<u8>> {
        let dir = self.transfer_dir(offer);
        let mut file = Vec::with_capacity(offer.size as usize);
        for k in 0..offer.chunks() {
            file.extend(std::fs::read(dir.join(format!("{k}.chunk")))?);
        }
        Ok(file)
    }

    fn discard(&mut self, offer: &Offer) -> std::io::Result<()> {
        match std::fs::remove_dir_all(self.transfer_dir(offer)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }

    fn pending(&mut self) -> std::io::Result<Option<Offer>> {
        let entries = match std::fs::read_dir(&self.dir) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(e),
        };
        // The most recently touched transfer with a readable offer.
        let mut best: Option<(std::time::SystemTime, Offer)> = None;
        for entry in entries {
            let path = entry?.path().join("offer");
            let Ok(bytes) = std::fs::read(&path) else {
                continue;
            };
            let Ok(offer) = postcard::from_bytes::<Offer>(&bytes) else {
                continue;
            };
            let modified = std::fs::metadata(&path)?.modified()?;
            if best.as_ref().is_none_or(|(t, _)| modified > *t) {
                best = Some((modified, offer));
            }
        }
        Ok(best.map(|(_, offer)| offer))
    }
}
