//! MAVLink 2 message signing (<https://mavlink.io/en/guide/message_signing.html>): the team's
//! secret key, read from `--mavlink-signing-key FILE`. The signatures themselves are the
//! `mavlink` crate's (`SigningData`: HMAC-SHA-256 truncated to 48 bits, timestamps that must
//! grow per link, system and component, so a replayed packet is refused too).
//!
//! The file holds the 32-byte key as 64 hexadecimal digits (one line; what
//! `printf %s PASSPHRASE | sha256sum` prints is MAVProxy's and Mission Planner's key for that
//! passphrase), or the 32 bytes themselves. It must be readable by its owner only: the key
//! lets anyone who reads it command the vehicles.

use std::fmt;
use std::io::Read;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};

use mavlink::{SigningConfig, SigningData};

/// A team's MAVLink signing key.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct SigningKey([u8; 32]);

impl fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Never printed, not even in a debug log.
        f.write_str("SigningKey(..)")
    }
}

/// Why a signing key file was refused.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    #[error("--mavlink-signing-key {}: cannot read it", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("--mavlink-signing-key {}: {problem}", path.display())]
    Invalid { path: PathBuf, problem: KeyProblem },
}

/// What makes a key file's contents no key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum KeyProblem {
    #[error("not a regular file")]
    NotAFile,
    #[error("readable or writable by others (mode {mode:o}); the key commands the vehicles: chmod 600 it")]
    Exposed { mode: u32 },
    #[error("expected 64 hexadecimal digits (the 32-byte key) or the 32 bytes themselves, found {bytes} bytes")]
    Length { bytes: usize },
    /// An all-zero key means "signing off" to MAVLink (SETUP_SIGNING).
    #[error("the key is all zeros, which MAVLink reads as signing disabled")]
    Zero,
}

/// The largest key file read (a key line is 65 bytes).
const MAX_KEY_FILE_BYTES: u64 = 4096;

impl SigningKey {
    /// The key of `path`: owner-only, 64 hex digits or 32 bytes.
    pub fn load(path: &Path) -> Result<Self, KeyError> {
        let invalid = |problem: KeyProblem| KeyError::Invalid {
            path: path.to_path_buf(),
            problem,
        };
        let read = |source| KeyError::Read {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::open(path).map_err(read)?;
        let meta = file.metadata().map_err(read)?;
        if !meta.is_file() {
            return Err(invalid(KeyProblem::NotAFile));
        }
        let mode = meta.permissions().mode();
        if mode & 0o077 != 0 {
            return Err(invalid(KeyProblem::Exposed { mode: mode & 0o777 }));
        }
        let mut bytes = Vec::new();
        file.take(MAX_KEY_FILE_BYTES)
            .read_to_end(&mut bytes)
            .map_err(read)?;
        parse_key(&bytes).map(SigningKey).map_err(invalid)
    }

    /// The crate's signing state for one link: outgoing messages signed with `link_id`,
    /// incoming ones accepted only when signed with this key (never unsigned).
    pub fn signing_data(&self, link_id: u8) -> SigningData {
        SigningData::from_config(SigningConfig::new(self.0, link_id, true, false))
    }
}

/// A key file's bytes: 64 hex digits (surrounding white space allowed) or exactly 32 bytes.
fn parse_key(bytes: &[u8]) -> Result<[u8; 32], KeyProblem> {
    let text = std::str::from_utf8(bytes).map(str::trim);
    if let Ok(hex) = text {
        if hex.len() == 64 && hex.bytes().all(|b| b.is_ascii_hexdigit()) {
            let mut key = [0u8; 32];
            for (k, pair) in key.iter_mut().zip(hex.as_bytes().chunks(2)) {
                let digits = std::str::from_utf8(pair).unwrap_or("00");
                *k = u8::from_str_radix(digits, 16).unwrap_or(0);
            }
            return check_not_zero(key);
        }
    }
    match <[u8; 32]>::try_from(bytes) {
        Ok(key) => check_not_zero(key),
        Err(_) => Err(KeyProblem::Length { bytes: bytes.len() }),
    }
}

/// An all-zero key means "signing off" to MAVLink (SETUP_SIGNING): refused as a key.
fn check_not_zero(key: [u8; 32]) -> Result<[u8; 32], KeyProblem> {
    if key.iter().all(|&b| b == 0) {
        return Err(KeyProblem::Zero);
    }
    Ok(key)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_and_raw_keys_parse_and_others_are_refused() {
        let hex = "00112233445566778899aabbccddeeff00112233445566778899AABBCCDDEEFF\n";
        let key = parse_key(hex.as_bytes()).unwrap();
        assert_eq!(key[1], 0x11);
        assert_eq!(key[31], 0xff);
        assert_eq!(parse_key(&key).unwrap(), key);
        assert_eq!(parse_key(b"abc"), Err(KeyProblem::Length { bytes: 3 }));
        assert!(parse_key(b"abc")
            .unwrap_err()
            .to_string()
            .contains("found 3 bytes"));
        assert_eq!(parse_key(&[0u8; 32]), Err(KeyProblem::Zero));
        let zeros = "0".repeat(64);
        assert!(parse_key(zeros.as_bytes()).is_err());
        let not_hex = "g".repeat(64);
        assert!(parse_key(not_hex.as_bytes())
            .unwrap_err()
            .to_string()
            .contains("64 hexadecimal digits"));
    }

    #[test]
    fn a_key_file_others_can_read_is_refused_naming_it() {
        let dir = std::env::temp_dir().join(format!("cdm-signing-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("key");
        std::fs::write(&path, "11".repeat(32)).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let err = SigningKey::load(&path).unwrap_err().to_string();
        assert!(err.contains(&path.display().to_string()) && err.contains("chmod 600"));
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        let key = SigningKey::load(&path).unwrap();
        assert_eq!(format!("{key:?}"), "SigningKey(..)");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
