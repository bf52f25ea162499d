//! What twinbench's tests share, instead of a copy per test file:
//! - [`Capture`]: a logger for [`fmu_export::Runtime`] that keeps every message;
//! - [`Noise`]: reproducible Gaussian noise (SplitMix64 + Box–Muller), no dependency;
//! - [`scratch`]: a scratch folder in the temporary directory, removed when dropped, so a
//!   test run leaves nothing behind;
//! - [`assert_contains`]: a text holds every one of a list of phrases.

use fmu_export::fmi2::fmi2Status;
use fmu_export::Logger;
use std::f64::consts::PI;
use std::sync::{Arc, Mutex};

/// Keeps every message a runtime logs (status, category, text), so tests can check what
/// an error names. Clones share the messages.
#[derive(Clone, Default)]
pub struct Capture(Arc<Mutex<Vec<(fmi2Status, String, String)>>>);

impl Logger for Capture {
    fn log(&self, status: fmi2Status, category: &str, message: &str) {
        if let Ok(mut m) = self.0.lock() {
            m.push((status, category.to_string(), message.to_string()));
        }
    }
}

impl Capture {
    /// A boxed clone to hand to a runtime (this one keeps reading the messages).
    pub fn boxed(&self) -> Box<dyn Logger> {
        Box::new(self.clone())
    }

    /// Every message text, in order.
    pub fn messages(&self) -> Vec<String> {
        self.0
            .lock()
            .map(|m| m.iter().map(|e| e.2.clone()).collect())
            .unwrap_or_default()
    }

    /// Every message text, one per line.
    pub fn text(&self) -> String {
        self.messages().join("\n")
    }

    /// The messages logged with `status`.
    pub fn with_status(&self, status: fmi2Status) -> Vec<String> {
        self.0
            .lock()
            .map(|m| {
                m.iter()
                    .filter(|e| e.0 == status)
                    .map(|e| e.2.clone())
                    .collect()
            })
            .unwrap_or_default()
    }

    pub fn clear(&self) {
        if let Ok(mut m) = self.0.lock() {
            m.clear();
        }
    }
}

/// Reproducible noise: SplitMix64 for uniform numbers, Box–Muller for Gaussian ones.
#[derive(Clone, Debug)]
pub struct Noise(u64);

impl Noise {
    pub fn new(seed: u64) -> Noise {
        Noise(seed)
    }

    /// Uniform in (0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Standard normal.
    pub fn gauss(&mut self) -> f64 {
        (-2.0 * self.uniform().ln()).sqrt() * (2.0 * PI * self.uniform()).cos()
    }
}

/// A scratch folder in the temporary directory, named after `tag`, removed when dropped.
pub fn scratch(tag: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("tb-{tag}-"))
        .tempdir()
        .expect("a scratch folder in the temporary directory")
}

/// Waits until `path` exists (a checkpoint a child process writes), at most `seconds`.
pub fn wait_for_file(path: &std::path::Path, seconds: u64) {
    let started = std::time::Instant::now();
    while !path.exists() {
        assert!(
            started.elapsed().as_secs() < seconds,
            "no {} after {seconds} s",
            path.display()
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// `text` contains every one of `parts`; otherwise the test fails naming the missing part
/// and showing the whole text.
#[track_caller]
pub fn assert_contains(text: &str, parts: &[&str]) {
    for p in parts {
        assert!(text.contains(p), "{p:?} is not in:\n{text}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_reproducible_and_roughly_standard_normal() {
        let (mut a, mut b) = (Noise::new(7), Noise::new(7));
        let xs: Vec<f64> = (0..20_000).map(|_| a.gauss()).collect();
        assert!(xs.iter().all(|&x| x.to_bits() == b.gauss().to_bits()));
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        // 20k samples: the standard error of the mean is 0.007, of the variance 0.01.
        assert!(mean.abs() < 0.03, "mean {mean}");
        assert!((var - 1.0).abs() < 0.05, "variance {var}");
    }

    #[test]
    fn scratch_folders_are_removed() {
        let d = scratch("kit");
        let p = d.path().to_path_buf();
        std::fs::write(p.join("x"), "1").unwrap();
        drop(d);
        assert!(!p.exists());
    }

    #[test]
    fn capture_keeps_messages_with_their_status() {
        let c = Capture::default();
        let l = c.boxed();
        l.log(fmi2Status::ERROR, "logStatusError", "bad");
        l.log(fmi2Status::OK, "logEvents", "fine");
        assert_eq!(c.messages(), ["bad", "fine"]);
        assert_eq!(c.with_status(fmi2Status::ERROR), ["bad"]);
    }

    #[test]
    fn assert_contains_names_the_missing_part() {
        assert_contains("a bad gain", &["bad", "gain"]);
        let e = std::panic::catch_unwind(|| assert_contains("a bad gain", &["bad", "loss"]))
            .unwrap_err();
        assert_eq!(
            e.downcast_ref::<String>().unwrap(),
            "\"loss\" is not in:\na bad gain"
        );
    }
}
