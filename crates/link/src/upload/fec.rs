//! Forward error correction for the tail of a file: how large a block to
//! protect and with how many Reed-Solomon repair shards.

use std::collections::BTreeMap;

use crate::wire::Offer;

/// The tail block a sender protects, and how many repair shards. The
/// block spans four round trips of chunks: a chunk lost before it is
/// NAKed and resent (twice, if need be) before the first pass ends (at
/// least 64 chunks: on a fast link a round trip is a few chunks). A repair
/// shard costs one chunk's time on the link; a shortfall costs about two
/// round trips after the end: shards are added while the chance of a
/// shortfall, times that, outweighs one more shard.
pub(crate) fn tail_block(
    chunks: u32,
    chunk_bytes: u32,
    loss_hint: f64,
    rtt_hint_ns: u64,
    pace_bit_s: Option<f64>,
) -> (u32, u32) {
    let p = loss_hint;
    if !(p > 0.0 && p < 1.0) || chunks == 0 {
        return (chunks, 0);
    }
    let per_chunk_bits = 8.0 * (f64::from(chunk_bytes) + 64.0);
    let rtt_s = rtt_hint_ns as f64 * 1e-9;
    let (in_four_rtt, chunk_s) = match pace_bit_s {
        Some(rate) => (
            (4.0 * rtt_s * rate / per_chunk_bits).ceil() as u32,
            per_chunk_bits / rate,
        ),
        None => (256, 0.0),
    };
    let block = chunks.min(in_four_rtt.clamp(64, 4096));
    let n = f64::from(block);
    let mut repairs = (n * p / (1.0 - p)).ceil() as u32;
    // A shortfall is found at the end of the file, asked for and resent:
    // about two round trips.
    while repairs < 4096 && shortfall_probability(block, repairs, p) * 2.0 * rtt_s > chunk_s {
        repairs += 1;
    }
    (chunks - block, repairs.max(1))
}

/// The chance that more than `repairs` of `block + repairs` shards are
/// lost, each with probability `p`.
fn shortfall_probability(block: u32, repairs: u32, p: f64) -> f64 {
    let n = block + repairs;
    // P(X <= repairs) for X ~ Binomial(n, p), term by term in logs.
    let (ln_p, ln_q) = (p.ln(), (1.0 - p).ln());
    let mut ln_term = f64::from(n) * ln_q;
    let mut held = ln_term.exp();
    for k in 1..=repairs.min(n) {
        ln_term += (f64::from(n - k + 1) / f64::from(k)).ln() + ln_p - ln_q;
        held += ln_term.exp();
    }
    (1.0 - held).max(0.0)
}

/// The repair shards of `offer`'s tail block (`offer.fec_repairs` of them,
/// each a chunk long; the last chunk is padded with zeros).
pub(crate) fn repair_shards(file: &[u8], offer: &Offer) -> Result<Vec<Vec<u8>>, String> {
    let size = offer.chunk_size as usize;
    let originals = (offer.fec_from..offer.chunks()).map(|k| {
        let from = k as usize * size;
        let mut shard = file[from..(from + size).min(file.len())].to_vec();
        shard.resize(size, 0);
        shard
    });
    reed_solomon_simd::encode(
        (offer.chunks() - offer.fec_from) as usize,
        offer.fec_repairs as usize,
        originals,
    )
    .map_err(|e| e.to_string())
}

/// The tail block's missing chunks (by their index in the block) from the
/// chunks held (index in the block, padded to a chunk) and the repair
/// shards held (by shard index).
pub(crate) fn restore(
    offer: &Offer,
    originals: Vec<(usize, Vec<u8>)>,
    repairs: &BTreeMap<u32, Vec<u8>>,
) -> Result<BTreeMap<usize, Vec<u8>>, String> {
    reed_solomon_simd::decode(
        (offer.chunks() - offer.fec_from) as usize,
        offer.fec_repairs as usize,
        originals,
        repairs.iter().map(|(&i, d)| (i as usize, d)),
    )
    .map_err(|e| e.to_string())
}
