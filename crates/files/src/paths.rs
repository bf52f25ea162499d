//! Paths named inside files, resolved against the file's own folder.
//!
//! A system file that says `fmus.vehicle = "../fmu/vehicle.fmu"` means the FMU beside its
//! own folder, not beside the working directory: `twinbench run my_lap/system.toml`,
//! `cd my_lap && twinbench run system.toml` and the Python package's `run("my_lap/system.toml")`
//! must all find the same file. So a file's folder is made absolute first
//! ([`folder_of`]), then the names in it are joined to that folder ([`resolve`]); the
//! result is absolute, and normalised ([`normalize`]) so that messages print
//! `/work/systems/rls_v.toml`, not `/work/studies/../systems/rls_v.toml`.

use std::path::{Component, Path, PathBuf};

/// `path` made absolute against the working directory and normalised. A path that is
/// already absolute is only normalised. Without a working directory (it was removed), the
/// path stays relative: an error about it then names it as the user wrote it.
pub fn absolute(path: &Path) -> PathBuf {
    if path.is_absolute() {
        return normalize(path);
    }
    match std::env::current_dir() {
        Ok(cwd) => normalize(&cwd.join(path)),
        Err(_) => normalize(path),
    }
}

/// The folder of the file `path` names, absolute and normalised (`system.toml` →
/// the working directory; `my_lap/system.toml` → `<cwd>/my_lap`).
pub fn folder_of(path: &Path) -> PathBuf {
    let file = absolute(path);
    match file.parent() {
        Some(p) => p.to_path_buf(),
        None => file,
    }
}

/// `name`, as written in a file whose folder is `base`: an absolute name as it is, a
/// relative one joined to `base`; normalised either way. `base` should come from
/// [`folder_of`] so that the result is absolute.
pub fn resolve(base: &Path, name: &Path) -> PathBuf {
    if name.is_absolute() {
        normalize(name)
    } else {
        normalize(&base.join(name))
    }
}

/// `path` without `.` steps and with `a/..` folded, as long as folding gives the same file:
/// `a/..` is kept where `a` is a symbolic link (the OS then climbs from the link's target,
/// not from the folder holding the link). Leading `..` of a relative path stay.
pub fn normalize(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    // How many trailing components of `out` may be folded away by a `..`: the ones pushed
    // as plain names (not a root, not a kept `..`).
    let mut foldable = 0usize;
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if foldable > 0 && !is_symlink(&out) {
                    out.pop();
                    foldable -= 1;
                } else if out.has_root() && out.parent().is_none() {
                    // `/..` is `/`.
                } else {
                    out.push("..");
                    foldable = 0;
                }
            }
            Component::Normal(n) => {
                out.push(n);
                foldable += 1;
            }
            Component::RootDir | Component::Prefix(_) => {
                out.push(c.as_os_str());
                foldable = 0;
            }
        }
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    out
}

/// `path` relative to the folder `base` (both absolute and normalised), for a file in
/// `base` to name `path` with: `/work/fmu` from `/work/my_lap` is `../fmu`. Where no
/// relative path exists (another root), `path` itself.
pub fn relative_to(path: &Path, base: &Path) -> PathBuf {
    pathdiff::diff_paths(path, base).unwrap_or_else(|| path.to_path_buf())
}

fn is_symlink(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalize_folds_dots() {
        assert_eq!(
            normalize(Path::new("/x/studies/../systems/./rls_v.toml")),
            Path::new("/x/systems/rls_v.toml")
        );
        assert_eq!(normalize(Path::new("a/b/../../c")), Path::new("c"));
        assert_eq!(normalize(Path::new("../a/../b")), Path::new("../b"));
        assert_eq!(normalize(Path::new("../../a")), Path::new("../../a"));
        assert_eq!(normalize(Path::new("/../a")), Path::new("/a"));
        assert_eq!(normalize(Path::new("a/..")), Path::new("."));
        assert_eq!(normalize(Path::new("./")), Path::new("."));
    }

    #[test]
    fn resolve_against_the_files_folder() {
        let base = Path::new("/work/my_lap");
        assert_eq!(
            resolve(base, Path::new("track.csv")),
            Path::new("/work/my_lap/track.csv")
        );
        assert_eq!(
            resolve(base, Path::new("../fmu/vehicle.fmu")),
            Path::new("/work/fmu/vehicle.fmu")
        );
        assert_eq!(
            resolve(base, Path::new("/data/lap.csv")),
            Path::new("/data/lap.csv")
        );
    }

    #[test]
    fn relative_to_a_folder() {
        let rel = relative_to(Path::new("/work/fmu"), Path::new("/work/my_lap"));
        assert_eq!(rel, Path::new("../fmu"));
        assert_eq!(
            resolve(Path::new("/work/my_lap"), &rel),
            Path::new("/work/fmu")
        );
        assert_eq!(
            relative_to(Path::new("/work/my_lap/fmu"), Path::new("/work/my_lap")),
            Path::new("fmu")
        );
    }

    #[test]
    fn folder_of_a_relative_file_is_absolute() {
        let cwd = std::env::current_dir().unwrap();
        assert_eq!(folder_of(Path::new("system.toml")), cwd);
        assert_eq!(
            folder_of(Path::new("my_lap/system.toml")),
            cwd.join("my_lap")
        );
        assert_eq!(folder_of(Path::new("./my_lap/../system.toml")), cwd);
        assert!(folder_of(Path::new("a/b.toml")).is_absolute());
    }

    #[test]
    fn a_symlinked_folder_is_not_folded() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real/inner");
        std::fs::create_dir_all(&real).unwrap();
        let link = dir.path().join("link");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        std::fs::write(dir.path().join("real/x.txt"), "x").unwrap();
        // link/.. is `real`, not `dir`: the normalised path must still name real/x.txt.
        let p = normalize(&link.join("../x.txt"));
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "x");
        // A plain folder folds.
        assert_eq!(
            normalize(&real.join("../x.txt")),
            dir.path().join("real/x.txt")
        );
    }
}
