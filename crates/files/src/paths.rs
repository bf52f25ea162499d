//! Paths named inside files, resolved against the file's own folder.
//!
//! A system file that says `fmus.vehicle = "../fmu/vehicle.fmu"` means the FMU beside its
//! own folder, not beside the working directory: `twinbench run my_lap/system.toml`,
//! `cd my_lap && twinbench run system.toml` and the Python package's `run("my_lap/system.toml")`
//! must all find the same file. So a file's folder is made absolute first
//! ([`folder_of`]), then the names in it are joined to that folder ([`resolve`]); the
//! result is absolute, and normalised ([`normalize`]) so that messages print
//! `/work/systems/rls_v.toml`, not `/work/studies/../systems/rls_v.toml`.
//!
//! A **mirror** ([`register_mirror`]) is a folder that holds another machine's files at
//! their absolute paths below it: a cluster worker without the coordinator's disk keeps a
//! study's files there (`<mirror>/home/me/project/studies/lap.toml`). A relative name in a
//! mirrored file then resolves inside the mirror by itself; an absolute one is taken as
//! the coordinator's path and resolved inside the mirror too; [`unmirror`] gives a mirrored
//! path back as the coordinator names it (for digests and messages).

use std::path::{Component, Path, PathBuf};
use std::sync::RwLock;

/// The mirrors of this process ([`register_mirror`]).
static MIRRORS: RwLock<Vec<PathBuf>> = RwLock::new(Vec::new());

/// Take `root` (absolute) as a mirror of another machine's files: every file the
/// coordinator names `/a/b` is `root/a/b`. Registering one twice is harmless.
pub fn register_mirror(root: &Path) {
    let root = absolute(root);
    let mut mirrors = MIRRORS.write().unwrap_or_else(|p| p.into_inner());
    if !mirrors.contains(&root) {
        mirrors.push(root);
    }
}

/// The mirror `path` lies in, if any.
fn mirror_of(path: &Path) -> Option<PathBuf> {
    let mirrors = MIRRORS.read().unwrap_or_else(|p| p.into_inner());
    mirrors
        .iter()
        .filter(|root| path.starts_with(root))
        .max_by_key(|root| root.components().count())
        .cloned()
}

/// `path` as the machine whose files a mirror holds names it (`<mirror>/a/b` → `/a/b`);
/// a path in no mirror as it is.
pub fn unmirror(path: &Path) -> PathBuf {
    match mirror_of(path) {
        Some(root) => match path.strip_prefix(&root) {
            Ok(rest) => Path::new("/").join(rest),
            Err(_) => path.to_path_buf(),
        },
        None => path.to_path_buf(),
    }
}

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
/// [`folder_of`] so that the result is absolute. In a mirror (a file of the coordinator's
/// on a cluster worker), an absolute name is the coordinator's: resolved in the mirror.
pub fn resolve(base: &Path, name: &Path) -> PathBuf {
    if name.is_absolute() {
        match mirror_of(base) {
            Some(root) => normalize(&root.join(name.strip_prefix("/").unwrap_or(name))),
            None => normalize(name),
        }
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

    /// A mirror holds the coordinator's files at their paths: names in its files resolve
    /// inside it, relative or absolute, and its paths read back as the coordinator's.
    #[test]
    fn names_in_a_mirror_resolve_inside_it() {
        let root = Path::new("/srv/worker/mirrors/ab12");
        register_mirror(root);
        let base = root.join("home/me/studies");
        assert_eq!(
            resolve(&base, Path::new("../systems/lap.toml")),
            root.join("home/me/systems/lap.toml")
        );
        assert_eq!(
            resolve(&base, Path::new("/home/me/fmu/vehicle.fmu")),
            root.join("home/me/fmu/vehicle.fmu")
        );
        // Outside a mirror an absolute name stays as it is.
        assert_eq!(
            resolve(
                Path::new("/home/me/studies"),
                Path::new("/home/me/fmu/v.fmu")
            ),
            Path::new("/home/me/fmu/v.fmu")
        );
        assert_eq!(
            unmirror(&root.join("home/me/fmu/v.fmu")),
            Path::new("/home/me/fmu/v.fmu")
        );
        assert_eq!(
            unmirror(Path::new("/elsewhere/x")),
            Path::new("/elsewhere/x")
        );
    }

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
