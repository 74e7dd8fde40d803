//! Pinocchio and coal on the exact collision meshes (`scripts/collision_reference.py`, PyPI
//! `pin`), run as a child process beside our checks: the files it reads (configurations as CSV,
//! the checked pairs by link name), its answer read back (one 0/1 flag a configuration), and
//! how far a check of ours agrees with it. Skipped, with the reason printed, where Python or
//! `pin` is absent; never a dependency of either crate.

use std::path::{Path, PathBuf};

use selfmodel::core::error::{Error, Result};
use selfmodel::ik::solve::collision::CollisionCheck;

/// Joint vectors as CSV, one column per joint named as the description names it (what the
/// reference script reads).
pub fn joints_csv(path: &Path, names: &[String], rows: &[&[f64]]) -> Result<()> {
    let mut text = names.join(",") + "\n";
    for r in rows {
        let cells: Vec<String> = r.iter().map(|v| v.to_string()).collect();
        text += &(cells.join(",") + "\n");
    }
    selfmodel::core::atomic_file::write_bytes(path, text.as_bytes())
}

/// Where Pinocchio checks them: the description, the pairs we check, the scene.
pub struct Reference<'a> {
    pub python: &'a Path,
    pub urdf: &'a Path,
    pub pairs: PathBuf,
    pub scene: Option<&'a Path>,
}

impl Reference<'_> {
    /// Whether each row of `joints` (a CSV [`joints_csv`] wrote) collides on the exact
    /// meshes; `None`, with the reason printed, where the script cannot run.
    pub fn collides(&self, joints: &Path, out: &Path) -> Result<Option<Vec<bool>>> {
        let script = crate::workspace().join("scripts/collision_reference.py");
        let mut cmd = std::process::Command::new(self.python);
        cmd.arg(&script)
            .arg("--urdf")
            .arg(self.urdf)
            .arg("--joints")
            .arg(joints)
            .arg("--checked")
            .arg(&self.pairs)
            .arg("--out")
            .arg(out);
        if let Some(s) = self.scene {
            cmd.arg("--scene").arg(s);
        }
        let rows = std::fs::read_to_string(joints)
            .map_err(|e| Error::io(joints, e))?
            .lines()
            .count()
            .saturating_sub(1);
        let o = match run_limited(&mut cmd, REFERENCE_SECONDS)? {
            Ok(o) => o,
            Err(why) => {
                eprintln!(
                    "collision_reference: Pinocchio's check skipped ({} {why})",
                    self.python.display()
                );
                return Ok(None);
            }
        };
        if !o.status.success() {
            eprintln!(
                "collision_reference: Pinocchio's check skipped ({})",
                String::from_utf8_lossy(&o.stderr)
                    .lines()
                    .last()
                    .unwrap_or("")
            );
            return Ok(None);
        }
        // Its answer is a CSV of one flag a configuration (`collides,...`, 0 or 1 first): a
        // Python that printed or wrote anything else did not check them.
        let text = selfmodel::core::input_file::read_user_text(
            out,
            "reference's answer",
            selfmodel::core::input_file::MAX_TABLE_BYTES,
            "CSV",
        )
        .ok();
        let flags: Option<Vec<bool>> = text.as_deref().and_then(|text| {
            let mut lines = text.lines();
            (lines.next()?.starts_with("collides"))
                .then(|| {
                    lines
                        .map(|l| match l.split(',').next() {
                            Some("1") => Some(true),
                            Some("0") => Some(false),
                            _ => None,
                        })
                        .collect::<Option<Vec<bool>>>()
                })
                .flatten()
        });
        match flags {
            Some(flags) if flags.len() == rows => {
                eprint!("{}", String::from_utf8_lossy(&o.stdout));
                Ok(Some(flags))
            }
            _ => {
                eprintln!(
                    "collision_reference: Pinocchio's check skipped ({} did not answer with one 0/1 flag for each of the {rows} configurations in {})",
                    self.python.display(),
                    out.display()
                );
                let _ = std::fs::remove_file(out);
                Ok(None)
            }
        }
    }
}

/// The longest the reference's Python may take over one file of configurations (s): it
/// checks a thousand in seconds.
const REFERENCE_SECONDS: f64 = 600.0;

/// Run `cmd` to its end, its output collected, within `limit` seconds: `Ok(Err(why))` where
/// it cannot start or runs past the limit (then killed), `Err(Interrupted)` on Ctrl-C (the
/// child killed first).
fn run_limited(
    cmd: &mut std::process::Command,
    limit: f64,
) -> Result<std::result::Result<std::process::Output, String>> {
    use std::io::Read;
    use std::process::Stdio;
    let mut child = match (cmd.stdin(Stdio::null()).stdout(Stdio::piped()))
        .stderr(Stdio::piped())
        .spawn()
    {
        Ok(child) => child,
        Err(e) => return Ok(Err(format!("cannot run: {e}"))),
    };
    // Read on threads of their own: a child that fills a pipe would otherwise wait for ever.
    let drain = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut p) = pipe {
                let _ = (&mut p).take(1 << 20).read_to_end(&mut bytes);
                let _ = std::io::copy(&mut p, &mut std::io::sink());
            }
            bytes
        })
    };
    let stdout = drain(
        child
            .stdout
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let stderr = drain(
        child
            .stderr
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child
            .try_wait()
            .map_err(|e| Error::io(cmd.get_program(), e))?
        {
            break Some(status);
        }
        if selfmodel::core::interrupt::requested() || start.elapsed().as_secs_f64() > limit {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    selfmodel::core::interrupt::check(|| {
        "stopped during Pinocchio's check; nothing was kept".into()
    })?;
    let (stdout, stderr) = (
        stdout.join().unwrap_or_default(),
        stderr.join().unwrap_or_default(),
    );
    Ok(match status {
        Some(status) => Ok(std::process::Output {
            status,
            stdout,
            stderr,
        }),
        None => Err(format!("ran past {limit:.0} s and was stopped")),
    })
}

/// Share (%) of `part` in `whole`.
pub fn pct(part: usize, whole: usize) -> f64 {
    100.0 * part as f64 / whole.max(1) as f64
}

/// The files Pinocchio's check reads, in `out`: each named set of joint vectors
/// ([`joints_csv`]) and the checked pairs by link name (`pairs.json`, returned).
pub fn write_reference_inputs(
    out: &Path,
    check: &CollisionCheck,
    names: &[String],
    sets: &[(&str, Vec<&[f64]>)],
) -> Result<PathBuf> {
    for (file, rows) in sets {
        joints_csv(&out.join(file), names, rows)?;
    }
    let links = &check.robot.chain.links;
    let pairs: Vec<[&str; 2]> = (check.model.pairs.iter())
        .map(|&(a, b)| [links[a].as_str(), links[b].as_str()])
        .collect();
    let pairs_file = out.join("pairs.json");
    selfmodel::core::atomic_file::write_json(&pairs_file, &pairs)?;
    Ok(pairs_file)
}

/// The spheres against the meshes on the same configurations: of those the meshes find free,
/// the share the spheres call colliding (%), and of those the meshes find colliding, the
/// share the spheres call free (%).
pub fn agreement_pct(meshes: &[bool], spheres: &[bool]) -> (f64, f64) {
    let count = |mesh: bool, sphere: bool| {
        (meshes.iter().zip(spheres))
            .filter(|&(&m, &s)| m == mesh && s == sphere)
            .count()
    };
    let (free, hit) = (
        count(false, false) + count(false, true),
        count(true, true) + count(true, false),
    );
    (pct(count(false, true), free), pct(count(true, false), hit))
}
