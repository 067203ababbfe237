//! Fresh ed25519 keys. Their PEM forms are `twindrive_link::envelope`'s.

use ed25519_dalek::SigningKey;

/// A fresh key pair from the operating system's randomness.
pub fn generate_key() -> Result<SigningKey, getrandom::Error> {
    let mut secret = [0u8; 32];
    getrandom::fill(&mut secret)?;
    Ok(SigningKey::from_bytes(&secret))
}
