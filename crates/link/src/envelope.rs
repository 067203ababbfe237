//! Signed plans and the robot's rules for accepting one.
//!
//! A signed plan is one file: the magic bytes `TWDSIGN1`, the length of the
//! envelope (u32, little-endian), the envelope as compact JSON, its ed25519
//! signature (64 bytes), and the plan document (the exact bytes of
//! `plan.json`) compressed with zstd. The signature covers a domain label
//! and the envelope's bytes as they stand in the file; the envelope holds
//! the SHA-256 of the plan document's bytes and the plan's own content hash,
//! so the robot verifies, and stores, exactly what was signed.
//!
//! Keys are ed25519 (`ed25519-dalek`) in standard PEM: PKCS#8 for the
//! private key, SubjectPublicKeyInfo for the public one (OpenSSL reads both).

use ed25519_dalek::pkcs8::spki::der::pem::LineEnding;
use ed25519_dalek::pkcs8::{DecodePrivateKey, DecodePublicKey, EncodePrivateKey, EncodePublicKey};
use ed25519_dalek::{Signature, Signer};
pub use ed25519_dalek::{SigningKey, VerifyingKey};
use serde::{Deserialize, Serialize};
use twindrive_plan::MissionPlan;
pub use twindrive_plan::sha256_hex;

/// The first bytes of a signed plan.
pub const MAGIC: &[u8; 8] = b"TWDSIGN1";
/// Signed with the envelope, so a signature made for something else never
/// verifies here.
const DOMAIN: &[u8] = b"twindrive signed plan v1\0";
/// `format` of every envelope.
pub const ENVELOPE_FORMAT: &str = "twindrive-signed-plan";
pub const ENVELOPE_VERSION: u32 = 1;

/// What the master vouches for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Envelope {
    pub format: String,
    pub version: u32,
    /// The plan's content hash (its `sha256` field).
    pub plan_sha256: String,
    /// SHA-256 of the plan document's bytes as carried.
    pub plan_file_sha256: String,
    /// Length of the plan document.
    pub plan_bytes: u64,
    /// How the document travels: `twdplan1` (columns, see
    /// [`crate::plan_codec`]) or `zstd-json`; filled in by [`sign_plan`].
    #[serde(default)]
    pub plan_encoding: String,
    pub robot_id: String,
    /// Only grows: a robot accepts a plan only above the last it accepted.
    pub counter: u64,
    /// Valid from (Unix seconds).
    pub not_before_unix_s: u64,
    /// Valid until (Unix seconds).
    pub expires_unix_s: u64,
    /// SHA-256 of the twin's world (the scenario) the plan was rehearsed in.
    pub world_sha256: String,
    pub supervision: Supervision,
    /// When the robot is to hand control back.
    #[serde(default)]
    pub tolerances: Tolerances,
}

/// How far reality may depart from the twin's prediction before the robot
/// stops and hands control back; carried, and signed, with the plan.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Tolerances {
    /// Odometry this far from the plan's pose at that time (m).
    pub max_deviation_m: f64,
    /// The median, over `residual_window` ticks, of range readings' distance
    /// from the best-matching prediction (m).
    pub max_range_residual_m: f64,
    /// Ticks the range residual's median is taken over.
    pub residual_window: usize,
    /// A reading is compared with the plan's predictions this long (s)
    /// either side of now, and the best match counts.
    pub range_match_s: f64,
    /// A range reading at least `obstacle_shorter_by_m` shorter than the
    /// map explains, ending inside the corridor the plan sweeps over its
    /// next `obstacle_ahead_m` of travel (its footprint and `obstacle_margin_m`
    /// either side), in `obstacle_confirm` fresh readings in a row, is an
    /// obstacle on the path: the robot stops before it touches it.
    pub obstacle_ahead_m: f64,
    pub obstacle_shorter_by_m: f64,
    pub obstacle_margin_m: f64,
    pub obstacle_confirm: usize,
}

impl Default for Tolerances {
    fn default() -> Self {
        Self {
            max_deviation_m: 0.15,
            max_range_residual_m: 0.10,
            residual_window: 50,
            range_match_s: 0.5,
            obstacle_ahead_m: 1.0,
            obstacle_shorter_by_m: 0.10,
            obstacle_margin_m: 0.05,
            obstacle_confirm: 3,
        }
    }
}

impl Envelope {
    /// An envelope to sign for `robot_id`: valid from a minute before
    /// `now_unix_s` (slack for the robot's clock) for `valid_for_s`. The
    /// plan's own fields are filled in by [`sign_plan`].
    pub fn new(
        robot_id: &str,
        counter: u64,
        now_unix_s: u64,
        valid_for_s: u64,
        world_sha256: String,
        supervision: Supervision,
        tolerances: Tolerances,
    ) -> Self {
        Self {
            format: String::new(),
            version: 0,
            plan_sha256: String::new(),
            plan_file_sha256: String::new(),
            plan_bytes: 0,
            plan_encoding: String::new(),
            robot_id: robot_id.into(),
            counter,
            not_before_unix_s: now_unix_s.saturating_sub(60),
            expires_unix_s: now_unix_s.saturating_add(valid_for_s),
            world_sha256,
            supervision,
            tolerances,
        }
    }
}

/// How the robot is to be watched while it drives.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Supervision {
    /// Stop if nothing is heard from the master for this long; `None`: the
    /// plan runs to its end unsupervised.
    pub dead_man_timeout_s: Option<f64>,
}

/// Why a key, a file or a plan was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Rejection {
    #[error("{size} bytes, more than the {max} a signed plan may have")]
    TooLarge { size: usize, max: usize },
    #[error("not a signed plan: {0}")]
    Malformed(String),
    #[error("the signature does not verify against any trusted key")]
    BadSignature,
    #[error("for robot `{plan}`, and this is `{robot}`")]
    WrongRobot { plan: String, robot: String },
    #[error("counter {counter} is not above {last}, the last plan accepted (a replay?)")]
    Replay { counter: u64, last: u64 },
    #[error("not valid before {not_before} (now {now}, Unix seconds)")]
    NotYetValid { not_before: u64, now: u64 },
    #[error("expired at {expires} (now {now}, Unix seconds)")]
    Expired { expires: u64, now: u64 },
    #[error("the plan document does not match its envelope: {0}")]
    PlanMismatch(String),
    #[error("the plan is not usable: {0}")]
    PlanInvalid(String),
}

/// The private key as PKCS#8 v1 PEM (RFC 8410: the seed alone, which every
/// OpenSSL reads).
pub fn private_key_pem(key: &SigningKey) -> String {
    ed25519_dalek::pkcs8::KeypairBytes {
        secret_key: key.to_bytes(),
        public_key: None,
    }
    .to_pkcs8_pem(LineEnding::LF)
    .expect("an ed25519 key encodes")
    .to_string()
}

/// The public key as SubjectPublicKeyInfo PEM.
pub fn public_key_pem(key: &VerifyingKey) -> String {
    key.to_public_key_pem(LineEnding::LF)
        .expect("an ed25519 key encodes")
}

pub fn read_private_key_pem(text: &str) -> Result<SigningKey, String> {
    SigningKey::from_pkcs8_pem(text)
        .map_err(|e| format!("not an ed25519 private key in PKCS#8 PEM: {e}"))
}

pub fn read_public_key_pem(text: &str) -> Result<VerifyingKey, String> {
    VerifyingKey::from_public_key_pem(text)
        .map_err(|e| format!("not an ed25519 public key in PEM: {e}"))
}

/// `plan_encoding` of a plan that travels as columns ([`crate::plan_codec`]).
pub const ENCODING_COLUMNS: &str = "twdplan1";
/// `plan_encoding` of a plan that travels as zstd-compressed JSON.
pub const ENCODING_JSON: &str = "zstd-json";

/// The plan document from a signed file's payload, as its envelope says it
/// travels; nothing beyond the envelope's `plan_bytes` is decompressed.
fn unpack(envelope: &Envelope, payload: &[u8]) -> Result<Vec<u8>, Rejection> {
    match envelope.plan_encoding.as_str() {
        ENCODING_COLUMNS => {
            // The columns take about as much room as the JSON, and never
            // more than three times it.
            crate::plan_codec::decode(payload, envelope.plan_bytes.saturating_mul(3))
                .map_err(|e| Rejection::PlanMismatch(e.to_string()))
        }
        ENCODING_JSON | "" => zstd::bulk::decompress(payload, envelope.plan_bytes as usize)
            .map_err(|e| Rejection::PlanMismatch(format!("the compressed plan: {e}"))),
        other => Err(Rejection::Malformed(format!(
            "plan encoding `{other}`, expected `{ENCODING_COLUMNS}` or `{ENCODING_JSON}`"
        ))),
    }
}

/// Signs a plan document (the bytes of `plan.json`) into a signed plan
/// file. `envelope.plan_*` are filled in from the document.
pub fn sign_plan(
    key: &SigningKey,
    plan_json: &[u8],
    mut envelope: Envelope,
) -> Result<Vec<u8>, Rejection> {
    let plan: MissionPlan = serde_json::from_slice(plan_json)
        .map_err(|e| Rejection::PlanInvalid(format!("not a plan document: {e}")))?;
    plan.validate()
        .map_err(|e| Rejection::PlanInvalid(e.to_string()))?;
    envelope.format = ENVELOPE_FORMAT.into();
    envelope.version = ENVELOPE_VERSION;
    envelope.plan_sha256 = plan.sha256.clone();
    envelope.plan_file_sha256 = sha256_hex(plan_json);
    envelope.plan_bytes = plan_json.len() as u64;
    let compressed = match crate::plan_codec::encode(plan_json) {
        Some(c) => {
            envelope.plan_encoding = ENCODING_COLUMNS.into();
            c
        }
        None => {
            envelope.plan_encoding = ENCODING_JSON.into();
            zstd::bulk::compress(plan_json, 19)
                .map_err(|e| Rejection::Malformed(format!("compressing the plan: {e}")))?
        }
    };
    let env_bytes = serde_json::to_vec(&envelope).expect("an envelope serialises");
    let signature = key.sign(&signed_bytes(&env_bytes));
    let mut out = Vec::with_capacity(12 + env_bytes.len() + 64 + compressed.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&(env_bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(&env_bytes);
    out.extend_from_slice(&signature.to_bytes());
    out.extend_from_slice(&compressed);
    Ok(out)
}

fn signed_bytes(envelope: &[u8]) -> Vec<u8> {
    let mut m = DOMAIN.to_vec();
    m.extend_from_slice(envelope);
    m
}

/// The parts of a signed plan file, before any check.
struct Parts<'a> {
    envelope_bytes: &'a [u8],
    signature: Signature,
    compressed: &'a [u8],
}

fn split(bytes: &[u8]) -> Result<Parts<'_>, Rejection> {
    let bad = |m: &str| Rejection::Malformed(m.into());
    let rest = bytes
        .strip_prefix(MAGIC.as_slice())
        .ok_or_else(|| bad("it does not start with TWDSIGN1"))?;
    let (len, rest) = rest
        .split_first_chunk::<4>()
        .ok_or_else(|| bad("it ends before the envelope's length"))?;
    let len = u32::from_le_bytes(*len) as usize;
    if rest.len() < len + 64 {
        return Err(bad("it ends inside the envelope or the signature"));
    }
    let (envelope_bytes, rest) = rest.split_at(len);
    let (sig, compressed) = rest.split_at(64);
    let sig: [u8; 64] = sig.try_into().expect("64 bytes");
    Ok(Parts {
        envelope_bytes,
        signature: Signature::from_bytes(&sig),
        compressed,
    })
}

/// Reads a signed plan's envelope without checking anything (for people and logs).
pub fn peek_envelope(bytes: &[u8]) -> Result<Envelope, Rejection> {
    let parts = split(bytes)?;
    serde_json::from_slice(parts.envelope_bytes)
        .map_err(|e| Rejection::Malformed(format!("envelope: {e}")))
}

/// The plan document inside a signed plan, with nothing checked: for the
/// master that signed it (the robot only ever uses [`PlanGate::check`]).
pub fn open_unchecked(bytes: &[u8]) -> Result<Vec<u8>, Rejection> {
    let envelope = peek_envelope(bytes)?;
    let parts = split(bytes)?;
    unpack(&envelope, parts.compressed)
}

/// What a robot accepts plans by.
#[derive(Debug, Clone)]
pub struct PlanGate {
    pub robot_id: String,
    pub trusted: Vec<VerifyingKey>,
    /// Largest signed plan file, checked before anything is parsed.
    pub max_signed_bytes: usize,
    /// Largest plan document, checked before it is decompressed.
    pub max_plan_bytes: u64,
}

/// A plan that passed every check.
#[derive(Debug, Clone)]
pub struct AcceptedPlan {
    pub envelope: Envelope,
    /// The plan document's bytes: the master's `plan.json`, byte for byte.
    pub plan_json: Vec<u8>,
    pub plan: MissionPlan,
}

impl PlanGate {
    /// Checks a signed plan file at `now_unix_s` against the last counter
    /// this robot accepted. Nothing in the file is trusted until its
    /// signature verifies (`verify_strict`).
    pub fn check(
        &self,
        bytes: &[u8],
        last_counter: u64,
        now_unix_s: u64,
    ) -> Result<AcceptedPlan, Rejection> {
        if bytes.len() > self.max_signed_bytes {
            return Err(Rejection::TooLarge {
                size: bytes.len(),
                max: self.max_signed_bytes,
            });
        }
        let parts = split(bytes)?;
        let message = signed_bytes(parts.envelope_bytes);
        if !self
            .trusted
            .iter()
            .any(|k| k.verify_strict(&message, &parts.signature).is_ok())
        {
            return Err(Rejection::BadSignature);
        }
        let envelope: Envelope = serde_json::from_slice(parts.envelope_bytes)
            .map_err(|e| Rejection::Malformed(format!("envelope: {e}")))?;
        if envelope.format != ENVELOPE_FORMAT || envelope.version != ENVELOPE_VERSION {
            return Err(Rejection::Malformed(format!(
                "envelope `{}` version {}, expected `{ENVELOPE_FORMAT}` version {ENVELOPE_VERSION}",
                envelope.format, envelope.version
            )));
        }
        if envelope.robot_id != self.robot_id {
            return Err(Rejection::WrongRobot {
                plan: envelope.robot_id,
                robot: self.robot_id.clone(),
            });
        }
        if envelope.counter <= last_counter {
            return Err(Rejection::Replay {
                counter: envelope.counter,
                last: last_counter,
            });
        }
        if now_unix_s < envelope.not_before_unix_s {
            return Err(Rejection::NotYetValid {
                not_before: envelope.not_before_unix_s,
                now: now_unix_s,
            });
        }
        if now_unix_s >= envelope.expires_unix_s {
            return Err(Rejection::Expired {
                expires: envelope.expires_unix_s,
                now: now_unix_s,
            });
        }
        if envelope.plan_bytes > self.max_plan_bytes {
            return Err(Rejection::TooLarge {
                size: envelope.plan_bytes as usize,
                max: self.max_plan_bytes as usize,
            });
        }
        let plan_json = unpack(&envelope, parts.compressed)?;
        if plan_json.len() as u64 != envelope.plan_bytes
            || sha256_hex(&plan_json) != envelope.plan_file_sha256
        {
            return Err(Rejection::PlanMismatch(
                "its bytes do not hash to the signed SHA-256".into(),
            ));
        }
        let plan: MissionPlan = serde_json::from_slice(&plan_json)
            .map_err(|e| Rejection::PlanInvalid(e.to_string()))?;
        plan.validate()
            .map_err(|e| Rejection::PlanInvalid(e.to_string()))?;
        if plan.sha256 != envelope.plan_sha256 {
            return Err(Rejection::PlanMismatch(format!(
                "its content hash is {}, the envelope says {}",
                plan.sha256, envelope.plan_sha256
            )));
        }
        Ok(AcceptedPlan {
            envelope,
            plan_json,
            plan,
        })
    }
}
