//! Where a receiver keeps the chunks it has, and a store in memory.

use crate::wire::{Offer, TransferId};

/// Where a receiver keeps the chunks it has, across restarts.
pub trait ChunkStore {
    /// Starts or resumes `offer`'s transfer: which chunks are already held.
    fn open(&mut self, offer: &Offer) -> std::io::Result<Vec<bool>>;
    /// Keeps one chunk; once this returns, a restart still has it.
    fn put(&mut self, offer: &Offer, index: u32, data: &[u8]) -> std::io::Result<()>;
    /// One chunk held.
    fn get(&mut self, offer: &Offer, index: u32) -> std::io::Result<Vec<u8>>;
    /// The whole file, chunks in order.
    fn assemble(&mut self, offer: &Offer) -> std::io::Result<Vec<u8>>;
    /// Drops what is kept for the transfer (done, or to start over).
    fn discard(&mut self, offer: &Offer) -> std::io::Result<()>;
    /// A transfer opened and not yet discarded (after a restart: the one to
    /// resume before the sender offers it again).
    fn pending(&mut self) -> std::io::Result<Option<Offer>>;
}

/// Chunks in memory. Clones share one store, so a test can "restart" a
/// receiver and keep what it had durably.
#[derive(Debug, Clone, Default)]
pub struct MemoryStore {
    inner: std::sync::Arc<std::sync::Mutex<MemoryInner>>,
}

#[derive(Debug, Default)]
struct MemoryInner {
    chunks: std::collections::HashMap<TransferId, Vec<Option<Vec<u8>>>>,
    pending: Option<Offer>,
}

impl ChunkStore for MemoryStore {
    fn open(&mut self, offer: &Offer) -> std::io::Result<Vec<bool>> {
        let mut inner = self.inner.lock().expect("store lock");
        inner.pending = Some(*offer);
        let chunks = inner
            .chunks
            .entry(offer.transfer)
            .or_insert_with(|| vec![None; offer.chunks() as usize]);
        Ok(chunks.iter().map(Option::is_some).collect())
    }

    fn put(&mut self, offer: &Offer, index: u32, data: &[u8]) -> std::io::Result<()> {
        let mut inner = self.inner.lock().expect("store lock");
        let chunks = inner
            .chunks
            .entry(offer.transfer)
            .or_insert_with(|| vec![None; offer.chunks() as usize]);
        chunks[index as usize] = Some(data.to_vec());
        Ok(())
    }

    fn get(&mut self, offer: &Offer, index: u32) -> std::io::Result<Vec<u8>> {
        let inner = self.inner.lock().expect("store lock");
        inner
            .chunks
            .get(&offer.transfer)
            .and_then(|c| c.get(index as usize)?.clone())
            .ok_or_else(|| std::io::Error::other("no such chunk"))
    }

    fn assemble(&mut self, offer: &Offer) -> std::io::Result<Vec<u8>> {
        let inner = self.inner.lock().expect("store lock");
        let chunks = inner
            .chunks
            .get(&offer.transfer)
            .ok_or_else(|| std::io::Error::other("no such transfer"))?;
        let mut file = Vec::with_capacity(offer.size as usize);
        for c in chunks {
            let c = c
                .as_ref()
                .ok_or_else(|| std::io::Error::other("a chunk is missing"))?;
            file.extend_from_slice(c);
        }
        Ok(file)
    }

    fn discard(&mut self, offer: &Offer) -> std::io::Result<()> {
        let mut inner = self.inner.lock().expect("store lock");
        inner.chunks.remove(&offer.transfer);
        if inner.pending.is_some_and(|p| p.transfer == offer.transfer) {
            inner.pending = None;
        }
        Ok(())
    }

    fn pending(&mut self) -> std::io::Result<Option<Offer>> {
        Ok(self.inner.lock().expect("store lock").pending)
    }
}
