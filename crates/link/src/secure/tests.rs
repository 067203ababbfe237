use std::sync::{Arc, Mutex};

use rand::{RngExt, SeedableRng};

use super::*;

fn key(seed: u8) -> SigningKey {
    SigningKey::from_bytes(&[seed; 32])
}

type Shared = Arc<Mutex<MemoryEpochs>>;

/// A master and a robot channel of robot `id`, on stores that outlive
/// them (a restart is a new channel on the same store).
struct Pair {
    master_key: SigningKey,
    robot_key: SigningKey,
    id: &'static str,
    master_store: Shared,
    robot_store: Shared,
}

impl Pair {
    fn new() -> Self {
        Self {
            master_key: key(1),
            robot_key: key(2),
            id: "rover",
            master_store: Shared::default(),
            robot_store: Shared::default(),
        }
    }
    fn master(&self) -> Channel {
        Channel::new(
            Role::Master,
            &self.master_key,
            &self.robot_key.verifying_key(),
            self.id,
            Box::new(self.master_store.clone()),
        )
        .unwrap()
    }
    fn robot(&self) -> Channel {
        Channel::new(
            Role::Robot,
            &self.robot_key,
            &self.master_key.verifying_key(),
            self.id,
            Box::new(self.robot_store.clone()),
        )
        .unwrap()
    }
}

#[test]
fn sealed_messages_open_both_ways_with_the_stated_overhead() {
    let p = Pair::new();
    let (mut m, mut r) = (p.master(), p.robot());
    for len in [0, 1, 100, 1400, 60_000] {
        let plain: Vec<u8> = (0..len).map(|i| (i * 7) as u8).collect();
        let up = m.seal(&plain).unwrap();
        assert_eq!(up.len(), plain.len() + OVERHEAD_BYTES);
        assert!(
            len < 32 || !up.windows(32).any(|w| w == &plain[..32]),
            "not encrypted"
        );
        assert_eq!(r.open(&up).unwrap(), plain);
        let down = r.seal(&plain).unwrap();
        assert_eq!(m.open(&down).unwrap(), plain);
        // A direction's key does not open the other's.
        assert_eq!(m.open(&up), Err(Refusal::NotAuthentic));
    }
}

#[test]
fn any_altered_byte_or_another_key_or_robot_is_not_authentic() {
    let p = Pair::new();
    let (mut m, mut r) = (p.master(), p.robot());
    let sealed = m.seal(b"heartbeat").unwrap();
    for i in 0..sealed.len() {
        for flip in [0x01u8, 0x80] {
            let mut bad = sealed.clone();
            bad[i] ^= flip;
            assert!(
                r.open(&bad).is_err(),
                "byte {i} flipped by {flip:#x} accepted"
            );
        }
    }
    // Another master's key, the right robot: refused.
    let mut other = Channel::new(
        Role::Master,
        &key(9),
        &p.robot_key.verifying_key(),
        "rover",
        Box::new(MemoryEpochs::default()),
    )
    .unwrap();
    assert_eq!(
        r.open(&other.seal(b"x").unwrap()),
        Err(Refusal::NotAuthentic)
    );
    // The right keys for another robot id: refused.
    let mut elsewhere = Channel::new(
        Role::Master,
        &p.master_key,
        &p.robot_key.verifying_key(),
        "rover2",
        Box::new(MemoryEpochs::default()),
    )
    .unwrap();
    assert_eq!(
        r.open(&elsewhere.seal(b"x").unwrap()),
        Err(Refusal::NotAuthentic)
    );
    // Plain bytes (an old, unsealed message): refused.
    assert!(matches!(
        r.open(b"\x00\x01plain"),
        Err(Refusal::NotSealed(_))
    ));
    assert!(matches!(r.open(&[]), Err(Refusal::NotSealed(_))));
    // The genuine one still opens: refusals changed nothing.
    assert_eq!(r.open(&sealed).unwrap(), b"heartbeat");
}

#[test]
fn a_replay_is_refused_and_reordering_is_not() {
    let p = Pair::new();
    let (mut m, mut r) = (p.master(), p.robot());
    let sealed: Vec<Vec<u8>> = (0..100u32)
        .map(|i| m.seal(&i.to_le_bytes()).unwrap())
        .collect();
    for i in (0..100).rev() {
        assert_eq!(r.open(&sealed[i]).unwrap(), (i as u32).to_le_bytes());
    }
    for s in &sealed {
        assert!(matches!(r.open(s), Err(Refusal::Replayed { .. })));
    }
}

#[test]
fn after_a_restart_of_either_end_nothing_sent_before_is_accepted_and_the_link_recovers() {
    let p = Pair::new();
    let (mut m, mut r) = (p.master(), p.robot());
    let before_up: Vec<_> = (0..5).map(|_| m.seal(b"up").unwrap()).collect();
    let before_down: Vec<_> = (0..5).map(|_| r.seal(b"down").unwrap()).collect();
    for s in &before_up[..3] {
        r.open(s).unwrap();
    }
    for s in &before_down[..3] {
        m.open(s).unwrap();
    }

    // The robot restarts: the master's current epoch is refused (its
    // messages 3 and 4 were never accepted, but 0..3 were, and a new run
    // cannot tell), and the robot asks for a newer one.
    let mut r = p.robot();
    for s in &before_up {
        assert!(matches!(r.open(s), Err(Refusal::StaleEpoch { .. })));
    }
    assert!(r.asks_resync());
    let ask = r.seal(b"status").unwrap();
    assert_eq!(ask.len(), b"status".len() + MAX_OVERHEAD_BYTES);
    // The master hears it (the robot's new epoch), moves on.
    let old_epoch = m.epoch();
    assert_eq!(m.open(&ask).unwrap(), b"status");
    assert!(m.epoch() > old_epoch);
    assert_eq!(r.open(&m.seal(b"fresh").unwrap()).unwrap(), b"fresh");
    assert!(!r.asks_resync());
    // Old messages both ways stay refused.
    for s in &before_up {
        assert!(r.open(s).is_err());
    }
    for s in &before_down {
        assert!(m.open(s).is_err());
    }

    // The master restarts: the same, the other way.
    let down_before: Vec<_> = (0..3).map(|_| r.seal(b"d").unwrap()).collect();
    m.open(&down_before[0]).unwrap();
    let mut m = p.master();
    assert!(matches!(
        m.open(&down_before[1]),
        Err(Refusal::StaleEpoch { .. })
    ));
    let ask = m.seal(b"heartbeat").unwrap();
    assert_eq!(r.open(&ask).unwrap(), b"heartbeat");
    assert_eq!(m.open(&r.seal(b"after").unwrap()).unwrap(), b"after");
    for s in &down_before {
        assert!(m.open(s).is_err());
    }
}

#[test]
fn forged_resync_requests_move_nothing() {
    let p = Pair::new();
    let (mut m, mut r) = (p.master(), p.robot());
    r.open(&m.seal(b"x").unwrap()).unwrap();
    let mut forged = r.seal(b"y").unwrap();
    // Set the resync bit and a floor: the tag no longer verifies.
    forged[0] |= 0x80;
    forged.splice(11..11, u32::MAX.to_be_bytes());
    let epoch = m.epoch();
    assert_eq!(m.open(&forged), Err(Refusal::NotAuthentic));
    assert_eq!(m.epoch(), epoch);
}

/// Random loss, duplication, reordering and restarts of either end, both
/// ways: every payload is accepted at most once, none sent before the
/// receiver's restart in an epoch it had accepted is accepted after it,
/// and after the last restart the link carries messages again.
#[test]
fn a_lossy_reordering_link_with_restarts_never_accepts_twice_and_recovers() {
    for seed in 0..20u64 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let p = Pair::new();
        let mut ends = [p.master(), p.robot()];
        // In flight per direction (0: up, 1: down): (id, sealed bytes,
        // the receiver's run it was sent during).
        let mut flight: [Vec<(u64, Vec<u8>)>; 2] = [vec![], vec![]];
        let mut accepted = std::collections::HashSet::new();
        let mut next_id = 0u64;
        // Ids sent before each end's latest restart (by the other end),
        // and the highest epoch of the other's it had accepted then.
        let mut restart_mark = [0u64; 2];
        let mut floor_at_restart = [0u32; 2];
        let steps = 3000;
        let mut delivered_after_last_restart = [0usize; 2];
        for step in 0..steps {
            let dir = rng.random_range(0..2usize);
            let (sender, receiver) = (dir, 1 - dir);
            match rng.random_range(0..10) {
                0..=3 => {
                    next_id += 1;
                    let s = ends[sender].seal(&next_id.to_le_bytes()).unwrap();
                    if rng.random_bool(0.8) {
                        flight[dir].push((next_id, s.clone()));
                    }
                    if rng.random_bool(0.1) {
                        flight[dir].push((next_id, s)); // duplicated
                    }
                }
                4..=8 if !flight[dir].is_empty() => {
                    let i = rng.random_range(0..flight[dir].len().min(40));
                    let (id, s) = flight[dir].remove(i);
                    if let Ok(plain) = ends[receiver].open(&s) {
                        let got = u64::from_le_bytes(plain.try_into().unwrap());
                        assert_eq!(got, id);
                        assert!(accepted.insert(id), "seed {seed}: {id} accepted twice");
                        let epoch = u32::from_be_bytes(s[1..5].try_into().unwrap());
                        assert!(
                            id > restart_mark[receiver] || epoch > floor_at_restart[receiver],
                            "seed {seed}: {id}, sent before the receiver restarted in an epoch it had accepted, accepted"
                        );
                        delivered_after_last_restart[receiver] += 1;
                    }
                    // Replay something already delivered, now and then.
                    if rng.random_bool(0.05) {
                        assert!(ends[receiver].open(&s).is_err());
                    }
                }
                9 if step < steps - 1000 && rng.random_bool(0.05) => {
                    let who = rng.random_range(0..2usize);
                    ends[who] = if who == 0 { p.master() } else { p.robot() };
                    restart_mark[who] = next_id;
                    let store = if who == 0 {
                        &p.master_store
                    } else {
                        &p.robot_store
                    };
                    floor_at_restart[who] = store.lock().unwrap().peer_floor;
                    delivered_after_last_restart = [0; 2];
                }
                _ => {}
            }
        }
        assert!(
            delivered_after_last_restart.iter().all(|&n| n > 50),
            "seed {seed}: the link did not recover: {delivered_after_last_restart:?}"
        );
    }
}

#[test]
fn a_robot_that_trusts_two_masters_answers_the_one_it_heard() {
    let p = Pair::new();
    let other = key(7);
    let mut robot = Peers::new(vec![
        p.robot(),
        Channel::new(
            Role::Robot,
            &p.robot_key,
            &other.verifying_key(),
            "rover",
            Box::new(MemoryEpochs::default()),
        )
        .unwrap(),
    ]);
    let mut second = Channel::new(
        Role::Master,
        &other,
        &p.robot_key.verifying_key(),
        "rover",
        Box::new(MemoryEpochs::default()),
    )
    .unwrap();
    let mut first = p.master();
    assert_eq!(robot.open(&second.seal(b"hi").unwrap()).unwrap(), b"hi");
    assert_eq!(second.open(&robot.seal(b"to 2").unwrap()).unwrap(), b"to 2");
    assert_eq!(
        robot.open(&first.seal(b"hello").unwrap()).unwrap(),
        b"hello"
    );
    assert_eq!(first.open(&robot.seal(b"to 1").unwrap()).unwrap(), b"to 1");
    let untrusted = Channel::new(
        Role::Master,
        &key(8),
        &p.robot_key.verifying_key(),
        "rover",
        Box::new(MemoryEpochs::default()),
    );
    assert_eq!(
        robot.open(&untrusted.unwrap().seal(b"x").unwrap()),
        Err(Refusal::NotAuthentic)
    );
}
