//! Frame output for ParaView: `frames/frame_NNNNN.vtu` with point data `displacement`, and
//! `series.pvd` listing them with their times (open the `.pvd`, then "Warp By Vector").

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use fem_core::io::vtu;
use fem_core::{TetMesh, Vec3};

/// Creates folder `path` if needed; `name` says what it is in errors (`the cache folder`,
/// `` `--out` ``) and `purpose` what it is for. A file in its place is refused plainly, not as
/// "File exists".
pub fn create_folder(path: &Path, name: &str, purpose: &str) -> Result<()> {
    check_folder(path, name, purpose)?;
    std::fs::create_dir_all(path)
        .with_context(|| format!("cannot create {name} {}", path.display()))
}

/// [`create_folder`]'s check alone, creating nothing: a file in the folder's place, or in the
/// place of a folder above it, and a link to nothing are refused naming the path at fault.
pub fn check_folder(path: &Path, name: &str, purpose: &str) -> Result<()> {
    // Without a trailing `/`, which makes a file's path "not a directory".
    let path: PathBuf = path.components().collect();
    for at in path.ancestors().filter(|a| !a.as_os_str().is_empty()) {
        let Ok(meta) = at.symlink_metadata() else {
            continue;
        };
        let whose = if at == path {
            format!("{name} {}", at.display())
        } else {
            format!("{} (above {name} {})", at.display(), path.display())
        };
        if meta.is_symlink() && !at.exists() {
            anyhow::bail!("{whose} is a link to nothing: give a folder {purpose}");
        }
        if !at.is_dir() {
            anyhow::bail!("{whose} is a file, not a folder: give a folder {purpose}");
        }
        // The first that exists is a folder: the rest above it are too.
        break;
    }
    Ok(())
}

/// Writes `bytes` to `path` atomically (its folder created if needed); an error names the file.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    fem_core::io::write_atomic(path, bytes)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Now, UTC, as ISO 8601 to the second (`2026-12-02T16:05:09Z`): when a report was written.
pub fn utc_now() -> String {
    let seconds = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    utc_timestamp(seconds)
}

/// `seconds` after 1970-01-01 UTC as ISO 8601 (the civil calendar from a day count, H. Hinnant's
/// `civil_from_days`).
fn utc_timestamp(seconds: u64) -> String {
    let (days, rest) = ((seconds / 86_400) as i64, seconds % 86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1_460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rest / 3_600,
        rest / 60 % 60,
        rest % 60
    )
}

/// Writes the frames of one simulation and, at the end, the series file.
#[derive(Debug)]
pub struct FrameWriter {
    dir: PathBuf,
    entries: Vec<(f64, String)>,
}

impl FrameWriter {
    /// Prepares `out`, removing the frames and the series file an earlier run left there;
    /// `out` and `out/frames/` are made by the first frame written (none when no frame is, so
    /// `run --every 0` leaves no empty folder per method).
    pub fn new(out: &Path) -> Result<Self> {
        let frames = out.join("frames");
        if frames.is_dir() {
            for entry in std::fs::read_dir(&frames)? {
                let p = entry?.path();
                if p.extension().is_some_and(|e| e == "vtu") {
                    std::fs::remove_file(&p)
                        .with_context(|| format!("cannot remove old frame {}", p.display()))?;
                }
            }
            // Left only when something else is in it.
            let _ = std::fs::remove_dir(&frames);
        }
        let series = out.join("series.pvd");
        if series.is_file() {
            std::fs::remove_file(&series)
                .with_context(|| format!("cannot remove old {}", series.display()))?;
        }
        Ok(Self {
            dir: out.to_path_buf(),
            entries: Vec::new(),
        })
    }

    /// Writes one frame with displacement `u` (3 per vertex).
    pub fn write(&mut self, mesh: &TetMesh, step: usize, time: f64, u: &[f64]) -> Result<()> {
        if self.entries.is_empty() {
            let frames = self.dir.join("frames");
            std::fs::create_dir_all(&frames)
                .with_context(|| format!("cannot create {}", frames.display()))?;
        }
        let name = format!("frames/frame_{step:05}.vtu");
        let disp: Vec<Vec3> = u
            .chunks_exact(3)
            .map(|c| Vec3::new(c[0], c[1], c[2]))
            .collect();
        vtu::write_vtu(&self.dir.join(&name), mesh, &[("displacement", &disp)], &[])?;
        self.entries.push((time, name));
        Ok(())
    }

    pub fn frames_written(&self) -> usize {
        self.entries.len()
    }

    /// Writes `series.pvd` for the frames written so far.
    pub fn finish(&self) -> Result<PathBuf> {
        let path = self.dir.join("series.pvd");
        vtu::write_pvd(&path, &self.entries)?;
        Ok(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh folder `NAME-PID` in the system's temporary folder.
    fn test_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// A file in a folder's place, above it, or behind a trailing `/`, and a link to nothing,
    /// are named as such, not as "File exists" or "Not a directory".
    #[test]
    fn folders_that_are_not_are_named() {
        let dir = test_dir("check-folder");
        let file = dir.join("afile");
        std::fs::write(&file, "x").unwrap();
        let said = |p: PathBuf| {
            create_folder(&p, "the cache folder", "for the stages' artifacts")
                .unwrap_err()
                .to_string()
        };
        let mut slash = file.clone().into_os_string();
        slash.push("/");
        for p in [file.clone(), PathBuf::from(slash)] {
            let e = said(p);
            assert!(
                e.ends_with(
                    "afile is a file, not a folder: give a folder for the stages' artifacts"
                ),
                "{e}"
            );
        }
        let e = said(file.join("sub"));
        assert!(e.contains("afile (above the cache folder"), "{e}");
        assert!(e.contains("is a file, not a folder"), "{e}");
        #[cfg(unix)]
        {
            let link = dir.join("dangling");
            std::os::unix::fs::symlink(dir.join("nowhere"), &link).unwrap();
            let e = said(link);
            assert!(e.contains("dangling is a link to nothing"), "{e}");
        }
        create_folder(&dir.join("a").join("b"), "the cache folder", "").unwrap();
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Dates against ones known: the epoch, a leap day, the turn of 2000, and today's kind.
    #[test]
    fn utc_timestamps_are_the_civil_calendar() {
        assert_eq!(utc_timestamp(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc_timestamp(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc_timestamp(946_684_799), "1999-12-31T23:59:59Z");
        assert_eq!(utc_timestamp(1_796_227_509), "2026-12-02T16:05:09Z");
        assert!(utc_now().starts_with("20") && utc_now().ends_with('Z'));
    }

    /// A file that cannot be written is named in the error, not only the system's reason.
    #[test]
    fn a_write_that_fails_names_the_file() {
        let dir = test_dir("output-write");
        let blocker = dir.join("a-file");
        std::fs::write(&blocker, "not a folder").unwrap();
        let target = blocker.join("curves").join("spectrum.csv");
        let err = format!("{:#}", write_file(&target, b"x").unwrap_err());
        assert!(err.contains(&target.display().to_string()), "{err}");
        let err = format!(
            "{:#}",
            create_folder(&blocker, "the output folder", "for it").unwrap_err()
        );
        assert!(err.contains("is a file, not a folder"), "{err}");
        write_file(&dir.join("ok.csv"), b"x").unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
