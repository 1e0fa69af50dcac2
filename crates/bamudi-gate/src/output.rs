//! Results directories written atomically.
//!
//! A command that writes several files (`calibrate`, `close-loop`) writes them into a hidden
//! staging directory beside the final one, `.<name>.partial-<pid>`, and renames it to its
//! final name only when every file is written ([`StagedDir::commit`]). So:
//!
//! * a failed or killed run never leaves a partial results directory under the final name
//!   (a killed run can leave the hidden staging directory, never a half-written result);
//! * a previous good result is untouched by a failed run;
//! * an existing non-empty directory is replaced only with `force` (the old one is moved
//!   aside, the new one renamed in, then the old one removed), otherwise refused;
//! * the destination is checked before any computation ([`StagedDir::prepare`]), so a bad
//!   `--out` is found in milliseconds, not after minutes of calibration.
//!
//! Single files go through [`bamudi::data::write_atomic`] (temporary name, then rename);
//! [`check_file_destination`] checks their destination up front.

use crate::error::{GateAppError, Result};
use std::path::{Path, PathBuf};

/// A results directory being written: files go to [`path`](Self::path) (the staging
/// directory) and appear under the final name at [`commit`](Self::commit). Dropped without a
/// commit (an error on the way), the staging directory is removed.
#[derive(Debug)]
pub struct StagedDir {
    target: PathBuf,
    staging: PathBuf,
    force: bool,
    committed: bool,
}

fn option_error(flag: &str, path: &Path, why: impl std::fmt::Display) -> GateAppError {
    GateAppError::Option(format!("{flag} {}: {why}", path.display()))
}

/// True when `dir` is a directory with at least one entry.
fn non_empty_dir(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|mut entries| entries.next().is_some())
}

/// The parent of `path` (`.` for a bare name).
fn parent_of(path: &Path) -> &Path {
    path.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

fn sibling(target: &Path, tag: &str) -> PathBuf {
    let name = target
        .file_name()
        .map_or("out".into(), |n| n.to_string_lossy().into_owned());
    parent_of(target).join(format!(".{name}.{tag}-{}", std::process::id()))
}

impl StagedDir {
    /// Checks the destination of a results directory given by the flag `flag` and creates the
    /// staging directory. Errors (naming the flag and the path): `target` is an existing
    /// file; `target` is a non-empty directory and `force` is false; the parent cannot be
    /// created or written.
    pub fn prepare(flag: &str, target: &Path, force: bool) -> Result<Self> {
        if target.exists() && !target.is_dir() {
            return Err(option_error(flag, target, "exists and is not a directory"));
        }
        if non_empty_dir(target) && !force {
            return Err(option_error(
                flag,
                target,
                "exists and is not empty (give --force to replace it, or choose a new directory)",
            ));
        }
        let parent = parent_of(target);
        std::fs::create_dir_all(parent)
            .map_err(|e| option_error(flag, target, format!("cannot create the parent: {e}")))?;
        let staging = sibling(target, "partial");
        if staging.exists() {
            std::fs::remove_dir_all(&staging).map_err(|e| {
                option_error(
                    flag,
                    &staging,
                    format!("cannot clear the staging directory: {e}"),
                )
            })?;
        }
        std::fs::create_dir(&staging)
            .map_err(|e| option_error(flag, target, format!("cannot write beside it: {e}")))?;
        Ok(Self {
            target: target.to_path_buf(),
            staging,
            force,
            committed: false,
        })
    }

    /// Where the files are written until the commit.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// The final directory.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Moves the finished directory to its final name (replacing an old one with `force`, or
    /// an empty one) and returns the final path.
    pub fn commit(mut self) -> Result<PathBuf> {
        let io = |path: &Path| {
            let path = path.display().to_string();
            move |source| GateAppError::Io { path, source }
        };
        if self.target.exists() {
            if non_empty_dir(&self.target) && !self.force {
                return Err(option_error(
                    "--out",
                    &self.target,
                    "was filled by someone else during the run (give --force to replace it)",
                ));
            }
            let old = sibling(&self.target, "old");
            std::fs::rename(&self.target, &old).map_err(io(&self.target))?;
            if let Err(e) = std::fs::rename(&self.staging, &self.target) {
                // Put the previous result back before reporting.
                let _ = std::fs::rename(&old, &self.target);
                return Err(io(&self.target)(e));
            }
            std::fs::remove_dir_all(&old).map_err(io(&old))?;
        } else {
            std::fs::rename(&self.staging, &self.target).map_err(io(&self.target))?;
        }
        self.committed = true;
        Ok(self.target.clone())
    }
}

impl Drop for StagedDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}

/// Checks the destination of a single output file given by `flag` before any computation:
/// not a directory, and its parent exists or can be created (created here).
pub fn check_file_destination(flag: &str, path: &Path) -> Result<()> {
    if path.is_dir() {
        return Err(option_error(
            flag,
            path,
            "is a directory, expected a file name",
        ));
    }
    if path.as_os_str().is_empty() {
        return Err(GateAppError::Option(format!("{flag}: empty path")));
    }
    std::fs::create_dir_all(parent_of(path))
        .map_err(|e| option_error(flag, path, format!("cannot create the parent: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("bamudi_output_{}_{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn entries(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_dropped_stage_leaves_nothing_and_a_commit_replaces_only_with_force() {
        let d = scratch("stage");
        let out = d.join("res");
        {
            let s = StagedDir::prepare("--out", &out, false).unwrap();
            std::fs::write(s.path().join("a.json"), "partial").unwrap();
        }
        assert_eq!(
            entries(&d),
            Vec::<String>::new(),
            "a failed run leaves nothing"
        );
        let s = StagedDir::prepare("--out", &out, false).unwrap();
        std::fs::write(s.path().join("a.json"), "good").unwrap();
        s.commit().unwrap();
        assert_eq!(entries(&d), vec!["res".to_string()]);
        let e = StagedDir::prepare("--out", &out, false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--out") && e.contains("--force"), "{e}");
        {
            let s = StagedDir::prepare("--out", &out, true).unwrap();
            std::fs::write(s.path().join("b.json"), "new").unwrap();
        }
        assert_eq!(std::fs::read_to_string(out.join("a.json")).unwrap(), "good");
        let s = StagedDir::prepare("--out", &out, true).unwrap();
        std::fs::write(s.path().join("b.json"), "new").unwrap();
        s.commit().unwrap();
        assert_eq!(entries(&out), vec!["b.json".to_string()], "no stale files");
        assert_eq!(entries(&d), vec!["res".to_string()]);
    }

    #[test]
    fn bad_destinations_are_refused_naming_the_flag() {
        let d = scratch("bad");
        let file = d.join("f.txt");
        std::fs::write(&file, "x").unwrap();
        let e = StagedDir::prepare("--out", &file, true)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--out") && e.contains("f.txt"), "{e}");
        let e = StagedDir::prepare("--out", &file.join("sub"), false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--out"), "{e}");
        let e = check_file_destination("--out", &d).unwrap_err().to_string();
        assert!(e.contains("is a directory"), "{e}");
        assert_eq!(entries(&d), vec!["f.txt".to_string()]);
    }
}
