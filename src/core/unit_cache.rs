//! A finished unit of a study (one model trained and scored), kept as JSON beside the unit's
//! git-ignored `checkpoint/` folder. A study resumed (`resume`) in a fresh clone, where the
//! checkpoints are gone, takes the units it finds here instead of training them again; a
//! unit is taken only if the settings it was made with (its fingerprint) are this run's.

use std::path::Path;

use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::Value;

use crate::core::atomic_file::write_json;
use crate::core::error::{Error, Result};

#[derive(Serialize, serde::Deserialize)]
struct Stored<T> {
    fingerprint: Value,
    value: T,
}

/// The value kept at `path`, if there is one made with `fingerprint` (a file that does not
/// read, or another fingerprint's, is no unit: it is made again and replaced).
pub fn load<T: DeserializeOwned>(path: &Path, fingerprint: &Value) -> Option<T> {
    let text = std::fs::read_to_string(path).ok()?;
    let stored: Stored<T> = serde_json::from_str(&text).ok()?;
    (stored.fingerprint == *fingerprint).then_some(stored.value)
}

/// Keep `value`, made with `fingerprint`, at `path` (atomically).
pub fn save<T: Serialize>(path: &Path, fingerprint: &Value, value: &T) -> Result<()> {
    write_json(
        path,
        &Stored {
            fingerprint: fingerprint.clone(),
            value,
        },
    )
}

/// The fingerprint of settings: their JSON.
pub fn fingerprint<T: Serialize>(settings: &T) -> Result<Value> {
    serde_json::to_value(settings).map_err(|e| Error::Config(format!("settings as JSON: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_unit_is_taken_back_only_with_its_fingerprint() {
        let dir = std::env::temp_dir().join(format!("unit_cache_{}", std::process::id()));
        let path = dir.join("unit.json");
        let made = serde_json::json!({"steps": 10});
        save(&path, &made, &vec![1.5f64, 2.0]).unwrap();
        assert_eq!(load::<Vec<f64>>(&path, &made), Some(vec![1.5, 2.0]));
        assert_eq!(
            load::<Vec<f64>>(&path, &serde_json::json!({"steps": 11})),
            None
        );
        assert_eq!(load::<Vec<f64>>(&dir.join("absent.json"), &made), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
