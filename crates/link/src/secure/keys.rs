//! The two ciphers of one master-robot pair, from their static ed25519
//! keys: X25519 on the keys' Montgomery forms (the ed25519 secret scalar
//! and the peer's point), HKDF-SHA256 over the shared secret, one
//! ChaCha20-Poly1305 key per direction.
//!
//! Using one key pair for signing and for Diffie-Hellman is analysed in
//! Thormarker, "On using the same key pair for Ed25519 and an X25519 based
//! KEM" (IACR ePrint 2021/509): safe for this use. The robot's key signs
//! nothing; the master's signs plans under a domain label of its own.

use chacha20poly1305::{ChaCha20Poly1305, Key, KeyInit};
use ed25519_dalek::{SigningKey, VerifyingKey};
use hkdf::Hkdf;
use sha2::Sha256;
use x25519_dalek::{PublicKey, StaticSecret};

/// Which end of the link this is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Master,
    Robot,
}

/// HKDF's salt: keys made for anything else never match these.
const SALT: &[u8] = b"twindrive link v1";

/// Why two keys make no link.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    #[error("the peer's public key is a point of small order: no shared secret")]
    WeakPeerKey,
}

/// The cipher each direction uses.
pub struct PairKeys {
    /// What this end sends.
    pub seal: ChaCha20Poly1305,
    /// What this end receives.
    pub open: ChaCha20Poly1305,
}

impl PairKeys {
    /// The keys of robot `robot_id`'s link, as `role` holds them: `own` is
    /// this end's signing key, `peer` the other end's public key.
    pub fn derive(
        role: Role,
        own: &SigningKey,
        peer: &VerifyingKey,
        robot_id: &str,
    ) -> Result<Self, KeyError> {
        let secret = StaticSecret::from(own.to_scalar_bytes());
        let shared = secret.diffie_hellman(&PublicKey::from(peer.to_montgomery().to_bytes()));
        if !shared.was_contributory() {
            return Err(KeyError::WeakPeerKey);
        }
        let own_public = own.verifying_key();
        let (master, robot) = match role {
            Role::Master => (own_public, *peer),
            Role::Robot => (*peer, own_public),
        };
        let hk = Hkdf::<Sha256>::new(Some(SALT), shared.as_bytes());
        let key = |direction: &[u8]| {
            let mut info = Vec::with_capacity(2 + robot_id.len() + 64 + direction.len());
            info.extend_from_slice(direction);
            info.push(robot_id.len() as u8);
            info.extend_from_slice(robot_id.as_bytes());
            info.extend_from_slice(master.as_bytes());
            info.extend_from_slice(robot.as_bytes());
            let mut okm = [0u8; 32];
            hk.expand(&info, &mut okm)
                .expect("32 bytes is a valid HKDF-SHA256 length");
            ChaCha20Poly1305::new(&Key::from(okm))
        };
        let (up, down) = (key(b"up"), key(b"down"));
        Ok(match role {
            Role::Master => Self {
                seal: up,
                open: down,
            },
            Role::Robot => Self {
                seal: down,
                open: up,
            },
        })
    }
}
