//! `twinbench cache info|prune`: the store of unpacked FMUs (docs/robustness.md, "The store
//! of unpacked FMUs").

use anyhow::{bail, Context};
use std::path::PathBuf;
use std::time::{Duration, SystemTime};
use tb_fmi::import::archive::{default_store_dir, prune_store, store_folders};

#[derive(clap::Args, Debug)]
pub struct CacheArgs {
    #[command(subcommand)]
    pub command: CacheCommand,
}

#[derive(clap::Subcommand, Debug)]
pub enum CacheCommand {
    /// Where the store is, what it holds and which folders running processes use.
    Info,
    /// Remove unpacked FMUs no running process uses: last used more than --older-than DAYS
    /// ago, then the least recently used until the store takes at most --max-size; always
    /// temporaries of killed processes and index entries of removed folders.
    Prune(PruneArgs),
}

#[derive(clap::Args, Debug)]
pub struct PruneArgs {
    /// Remove folders last used more than this many days ago (0: every unused folder).
    #[arg(long, value_name = "DAYS")]
    pub older_than: Option<f64>,
    /// Then remove the least recently used until the folders take at most this much
    /// (bytes, or with a unit: 500M, 2G).
    #[arg(long, value_name = "SIZE")]
    pub max_size: Option<String>,
}

/// `500M`, `2G`, `1.5GiB`, `1000` (bytes): decimal and binary units, as `du -h` prints.
fn parse_size(s: &str) -> anyhow::Result<u64> {
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let n: f64 = num
        .parse()
        .with_context(|| format!("--max-size {s}: not a size (e.g. 500M, 2G)"))?;
    let scale: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" => 1e3,
        "kib" => 1024.0,
        "m" | "mb" => 1e6,
        "mib" => 1024.0 * 1024.0,
        "g" | "gb" => 1e9,
        "gib" => 1024.0 * 1024.0 * 1024.0,
        "t" | "tb" => 1e12,
        other => bail!("--max-size {s}: unknown unit '{other}' (B, K, M, G, T; KiB, MiB, GiB)"),
    };
    let bytes = n * scale;
    if !bytes.is_finite() || !(0.0..=1e18).contains(&bytes) {
        bail!("--max-size {s}: out of range");
    }
    Ok(bytes as u64)
}

fn store() -> anyhow::Result<PathBuf> {
    default_store_dir().context(
        "no store of unpacked FMUs: none of TWINBENCH_CACHE, XDG_CACHE_HOME and HOME is set",
    )
}

fn shown(bytes: u64) -> String {
    match bytes {
        b if b >= 1 << 30 => format!("{:.1} GiB", b as f64 / (1u64 << 30) as f64),
        b if b >= 1 << 20 => format!("{:.1} MiB", b as f64 / (1u64 << 20) as f64),
        b if b >= 1 << 10 => format!("{:.1} KiB", b as f64 / 1024.0),
        b => format!("{b} B"),
    }
}

fn days_ago(t: SystemTime) -> String {
    let d = SystemTime::now()
        .duration_since(t)
        .unwrap_or_default()
        .as_secs_f64()
        / 86400.0;
    format!("{d:.1} days ago")
}

/// `prune`'s limits, checked before anything else (red team M17: a bad size passed when
/// there was no store yet).
fn prune_limits(p: &PruneArgs) -> anyhow::Result<(Option<Duration>, Option<u64>)> {
    let older_than = match p.older_than {
        Some(d) if !(d.is_finite() && (0.0..=36500.0).contains(&d)) => {
            bail!("--older-than {d}: a number of days in [0, 36500]")
        }
        Some(d) => Some(Duration::from_secs_f64(d * 86400.0)),
        None => None,
    };
    let max = p.max_size.as_deref().map(parse_size).transpose()?;
    Ok((older_than, max))
}

pub fn run(args: CacheArgs) -> anyhow::Result<()> {
    if let CacheCommand::Prune(p) = &args.command {
        prune_limits(p)?;
    }
    let store = store()?;
    if !store.is_dir() {
        println!("store    {} (not made yet)", store.display());
        return Ok(());
    }
    match args.command {
        CacheCommand::Info => {
            let folders = store_folders(&store)
                .with_context(|| format!("{}: cannot list", store.display()))?;
            let total: u64 = folders.iter().map(|f| f.bytes).sum();
            let in_use = folders.iter().filter(|f| f.in_use).count();
            println!("store    {}", store.display());
            println!(
                "folders  {} ({}), {in_use} in use by running processes",
                folders.len(),
                shown(total)
            );
            for f in folders.iter().rev() {
                println!(
                    "  {}  {:<28}  {:>10}  last used {}{}",
                    f.path.file_name().unwrap_or_default().to_string_lossy(),
                    model_of(&f.path),
                    shown(f.bytes),
                    days_ago(f.last_used),
                    if f.in_use {
                        ", in use"
                    } else if f.incomplete {
                        ", incomplete"
                    } else {
                        ""
                    }
                );
            }
        }
        CacheCommand::Prune(p) => {
            let (older_than, max) = prune_limits(&p)?;
            let r = prune_store(&store, older_than, max)
                .with_context(|| format!("{}: cannot prune", store.display()))?;
            let freed: u64 = r.removed.iter().map(|f| f.bytes).sum();
            println!("store    {}", store.display());
            println!(
                "removed  {} folders ({}), {} temporaries, {} index entries",
                r.removed.len(),
                shown(freed),
                r.temporaries,
                r.index_entries
            );
            println!("left     {}", shown(r.bytes_left));
            if r.kept_in_use > 0 {
                println!(
                    "kept     {} folders in use by running processes",
                    r.kept_in_use
                );
            }
        }
    }
    Ok(())
}

/// The model a store folder holds, as its model description names it: `vehicle (FMI 2.0)`
/// (the folder's name is a digest of the FMU's bytes; a user looks for the model). The
/// description is the importer's parse (FMI 2.0 or 3.0); its name is a supplier's text:
/// control characters dropped, at most 40 characters; `?` where it cannot be read.
fn model_of(folder: &std::path::Path) -> String {
    std::fs::read_to_string(folder.join("modelDescription.xml"))
        .ok()
        .and_then(|xml| tb_fmi::import::description::parse(&xml).ok())
        .map_or_else(
            || "?".into(),
            |d| {
                let name: String = d
                    .model_name
                    .chars()
                    .filter(|c| !c.is_control())
                    .take(40)
                    .collect();
                format!("{name} (FMI {})", d.fmi_version)
            },
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_take_units() {
        assert_eq!(parse_size("1000").unwrap(), 1000);
        assert_eq!(parse_size("500M").unwrap(), 500_000_000);
        assert_eq!(parse_size("2G").unwrap(), 2_000_000_000);
        assert_eq!(parse_size("1GiB").unwrap(), 1 << 30);
        assert_eq!(parse_size("1.5 kib").unwrap(), 1536);
        assert!(parse_size("5 furlongs").is_err());
        assert!(parse_size("-1").is_err());
    }
}
