//! Whether an external command's program is there at all, and its runs root takes run
//! directories, checked before any run: either missing would otherwise fail every run of
//! the design in turn.

use std::path::Path;

use super::{ExternalCommand, ExternalError};

impl<S> ExternalCommand<S> {
    /// Checks, before any run, that the program can be found: an absolute path must be an
    /// executable file, a bare name one in `PATH` (unless the model's `env` sets its own
    /// `PATH`, which only a run resolves). Every run would otherwise fail the same way,
    /// one after another (a setup failure is never retried, but each run meets it).
    /// A relative path with a directory is left to the run.
    pub fn check_program(&self) -> Result<(), ExternalError> {
        let program = Path::new(&self.program);
        let missing = |reason: String| ExternalError::Setting {
            key: "program".into(),
            reason,
        };
        if program.is_absolute() {
            return match std::fs::metadata(program) {
                Ok(m) if m.is_file() && is_executable(&m) => Ok(()),
                Ok(m) if m.is_file() => Err(missing(format!(
                    "`{}` is not executable (chmod +x it, or name its interpreter as the \
                     program)",
                    program.display()
                ))),
                Ok(_) => Err(missing(format!("`{}` is not a file", program.display()))),
                Err(e) => Err(missing(format!("`{}`: {e}", program.display()))),
            };
        }
        if program.components().count() > 1 || self.env.iter().any(|(k, _)| k == "PATH") {
            return Ok(());
        }
        let path = std::env::var_os("PATH").unwrap_or_default();
        let found = std::env::split_paths(&path).any(|dir| {
            std::fs::metadata(dir.join(program)).is_ok_and(|m| m.is_file() && is_executable(&m))
        });
        match found {
            true => Ok(()),
            false => Err(missing(format!(
                "`{}` is not an executable in PATH (a typo, or not installed?)",
                program.display()
            ))),
        }
    }

    /// Checks, before any run, that the runs root (`runs_root`) is or can be made a
    /// directory that takes run directories; it is made when missing. Every run would
    /// otherwise fail to set up, one after another, and be journaled as failed.
    pub fn check_runs_root(&self) -> Result<(), ExternalError> {
        let root = self.runs_root();
        self.dirs
            .check_writable()
            .map_err(|e| ExternalError::Setting {
                key: "runs_root".into(),
                reason: format!("{} takes no run directory: {e}", root.display()),
            })
    }
}

/// Whether a file's permissions let someone run it.
fn is_executable(meta: &std::fs::Metadata) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        meta.permissions().mode() & 0o111 != 0
    }
    #[cfg(not(unix))]
    {
        let _ = meta;
        true
    }
}
