//! What one end keeps across restarts about one link: its own sending
//! epoch (so no nonce is ever used twice) and the highest epoch of the
//! peer's it accepted (so nothing sent before a restart is accepted after
//! it). Storage is the caller's: a file on the robot and the master
//! (`twindrive-store`), memory in one process.

/// Storage of a link's epochs. Both calls keep what they are told
/// durably before they return; an error refuses the message (or the send)
/// rather than risk a reused nonce or an accepted replay.
pub trait EpochStore: Send {
    /// A sending epoch above every one this end used before with this
    /// peer, and at least `at_least`; kept before it is returned.
    fn next_epoch(&mut self, at_least: u32) -> Result<u32, String>;
    /// The highest epoch of the peer's accepted before (0: none).
    fn peer_floor(&self) -> u32;
    /// Keeps that the peer's `epoch` is accepted (before its first
    /// message is).
    fn raise_peer_floor(&mut self, epoch: u32) -> Result<(), String>;
}

/// Epochs in memory: one process's runs (the demo, experiments, tests),
/// where "a restart" is a new channel on the same store.
#[derive(Debug, Clone, Default)]
pub struct MemoryEpochs {
    pub epoch: u32,
    pub peer_floor: u32,
}

impl EpochStore for MemoryEpochs {
    fn next_epoch(&mut self, at_least: u32) -> Result<u32, String> {
        let next = self
            .epoch
            .checked_add(1)
            .ok_or("the epoch counter is exhausted")?
            .max(at_least);
        self.epoch = next;
        Ok(next)
    }

    fn peer_floor(&self) -> u32 {
        self.peer_floor
    }

    fn raise_peer_floor(&mut self, epoch: u32) -> Result<(), String> {
        self.peer_floor = self.peer_floor.max(epoch);
        Ok(())
    }
}

/// A shared store (`Arc<Mutex<_>>`): a test restarts an end by making a
/// new channel on the same store.
impl<S: EpochStore> EpochStore for std::sync::Arc<std::sync::Mutex<S>> {
    fn next_epoch(&mut self, at_least: u32) -> Result<u32, String> {
        self.lock().expect("epoch store").next_epoch(at_least)
    }
    fn peer_floor(&self) -> u32 {
        self.lock().expect("epoch store").peer_floor()
    }
    fn raise_peer_floor(&mut self, epoch: u32) -> Result<(), String> {
        self.lock().expect("epoch store").raise_peer_floor(epoch)
    }
}
