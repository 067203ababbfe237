//! Which counters of one sender's epoch have been seen: the highest, and a
//! bitmap of the [`WINDOW`] below it (a lossy link reorders; anything older
//! is refused as if seen).

/// Counters this far below the highest seen are still accepted once.
pub const WINDOW: u64 = 4096;
const WORDS: usize = (WINDOW / 64) as usize;

#[derive(Debug, Clone)]
pub struct ReplayWindow {
    /// One more than the highest counter accepted (0: none yet).
    next: u64,
    /// Bit `c % WINDOW` set: counter `c` (within the window) was accepted.
    bits: [u64; WORDS],
}

impl Default for ReplayWindow {
    fn default() -> Self {
        Self {
            next: 0,
            bits: [0; WORDS],
        }
    }
}

/// Why a counter is not new.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Seen {
    /// Accepted before.
    Replayed,
    /// Older than the window: it cannot be told apart from a replay.
    TooOld,
}

impl ReplayWindow {
    fn bit(counter: u64) -> (usize, u64) {
        let i = counter % WINDOW;
        ((i / 64) as usize, 1u64 << (i % 64))
    }

    /// Whether `counter` may be accepted (nothing changes).
    pub fn check(&self, counter: u64) -> Result<(), Seen> {
        if counter >= self.next {
            return Ok(());
        }
        if self.next - counter > WINDOW {
            return Err(Seen::TooOld);
        }
        let (w, b) = Self::bit(counter);
        if self.bits[w] & b != 0 {
            Err(Seen::Replayed)
        } else {
            Ok(())
        }
    }

    /// Marks `counter` accepted; [`Self::check`] must have allowed it.
    pub fn accept(&mut self, counter: u64) {
        if counter >= self.next {
            // Clear the bits of the counters the window slides past.
            let slide = counter + 1 - self.next;
            if slide >= WINDOW {
                self.bits = [0; WORDS];
            } else {
                for c in self.next..=counter {
                    let (w, b) = Self::bit(c);
                    self.bits[w] &= !b;
                }
            }
            self.next = counter + 1;
        }
        let (w, b) = Self::bit(counter);
        self.bits[w] |= b;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn every_counter_is_accepted_once_in_any_order_within_the_window() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        // Counters 0..20_000, each displaced by up to half the window.
        let mut order: Vec<(u64, u64)> = (0..20_000u64)
            .map(|c| (c + rng.random_range(0..WINDOW / 2), c))
            .collect();
        order.sort();
        let mut w = ReplayWindow::default();
        for &(_, c) in &order {
            assert_eq!(w.check(c), Ok(()), "counter {c}");
            w.accept(c);
            assert_eq!(w.check(c), Err(Seen::Replayed));
        }
        // Every one of them again: refused.
        for &(_, c) in &order {
            assert!(w.check(c).is_err(), "counter {c} accepted twice");
        }
        assert_eq!(w.check(20_000 - WINDOW - 1), Err(Seen::TooOld));
        assert_eq!(w.check(20_000), Ok(()));
    }

    #[test]
    fn a_jump_clears_what_the_window_slid_past() {
        let mut w = ReplayWindow::default();
        w.accept(5);
        w.accept(5 + WINDOW);
        // 5 is now too old; everything between is new.
        assert_eq!(w.check(5), Err(Seen::TooOld));
        assert_eq!(w.check(6 + WINDOW / 2), Ok(()));
        w.accept(10 * WINDOW);
        assert_eq!(w.check(10 * WINDOW), Err(Seen::Replayed));
        assert_eq!(w.check(10 * WINDOW - 1), Ok(()));
    }
}
