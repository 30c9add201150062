//! The meshed case of one hall, built once and cached, and the running of OpenFOAM
//! programs (each in its own process group, with a timeout, logs in a step directory).

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use kalibre_core::external::{
    log_tail, run_process, ProcessEnd, ProcessOutcome, ProcessSpec, RunDirs,
};

use super::geometry::CaseGeometry;
use super::{dicts, OpenFoamError, OpenFoamSettings};

/// Marks a case directory whose meshing finished and was checked.
const READY: &str = ".kalibre-ready";

/// Where cases are meshed before they are moved into place (under `cache_root`).
const MESH_BUILDS: &str = "mesh-builds";

/// What meshing produced.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshSummary {
    /// Cells of the fluid mesh.
    pub cells: usize,
    /// Patches other than `walls`, with their face counts.
    pub patches: Vec<(String, usize)>,
}

/// A meshed case directory (`constant`, `system`, `0.orig`), shared read-only by runs.
#[derive(Debug, Clone)]
pub struct CaseDir {
    dir: PathBuf,
    key: String,
    project_dir: PathBuf,
}

/// Finds a program in `PATH`.
pub(crate) fn which(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

fn write(path: &Path, text: &str) -> Result<(), OpenFoamError> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| OpenFoamError::io(parent, e))?;
    }
    std::fs::write(path, text).map_err(|e| OpenFoamError::io(path, e))
}

/// Runs one OpenFOAM program on `case` with its logs in `case/logs/<step>`.
pub(crate) fn run_step(
    case: &Path,
    project_dir: &Path,
    step: &str,
    program: &str,
    args: &[String],
    timeout: Duration,
) -> Result<(ProcessOutcome, PathBuf), OpenFoamError> {
    let logs = case.join("logs").join(step);
    std::fs::create_dir_all(&logs).map_err(|e| OpenFoamError::io(&logs, e))?;
    // PWD follows the working directory, or OpenFOAM warns that they differ.
    let env = [
        (
            "WM_PROJECT_DIR".to_string(),
            project_dir.display().to_string(),
        ),
        ("PWD".to_string(), logs.display().to_string()),
    ];
    let spec = ProcessSpec {
        program: OsStr::new(program),
        args,
        env: &env,
        dir: &logs,
        timeout,
        kill_grace: Duration::from_secs(5),
    };
    let out = run_process(&spec).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => OpenFoamError::NotInstalled(program.to_string()),
        _ => OpenFoamError::io(&logs, e),
    })?;
    Ok((out, logs))
}

fn case_arg(case: &Path) -> Vec<String> {
    vec!["-case".into(), case.display().to_string()]
}

impl CaseDir {
    /// The meshed case for `g` under `settings.cache_root`, named by `key`; built when
    /// absent (in a temporary directory renamed into place, so parallel builders never
    /// see half a case). A complete case under `legacy_key` (the name an earlier version
    /// gave the same case) is used as it is rather than meshed again.
    pub fn open_or_build(
        g: &CaseGeometry,
        settings: &OpenFoamSettings,
        key: &str,
        legacy_key: &str,
    ) -> Result<Self, OpenFoamError> {
        for p in [
            "blockMesh",
            "topoSet",
            "subsetMesh",
            "createPatch",
            "buoyantBoussinesqSimpleFoam",
        ] {
            if which(p).is_none() {
                return Err(OpenFoamError::NotInstalled(p.into()));
            }
        }
        let root = &settings.cache_root;
        std::fs::create_dir_all(root).map_err(|e| OpenFoamError::io(root, e))?;
        let root = std::path::absolute(root).map_err(|e| OpenFoamError::io(root, e))?;
        let legacy = root.join(format!("case-{legacy_key}"));
        if legacy_key != key
            && legacy.join(READY).is_file()
            && !root.join(format!("case-{key}")).join(READY).is_file()
        {
            return Ok(CaseDir {
                dir: legacy,
                key: legacy_key.to_string(),
                project_dir: settings.project_dir.clone(),
            });
        }
        let dir = root.join(format!("case-{key}"));
        let this = CaseDir {
            dir: dir.clone(),
            key: key.to_string(),
            project_dir: settings.project_dir.clone(),
        };
        if dir.join(READY).is_file() {
            return Ok(this);
        }
        // Built in a fresh directory marked as in use, so a builder killed midway (its
        // mesh can take minutes) leaves one the next sweep removes; a failed build's stays,
        // unmarked, for its logs.
        let builds = RunDirs::new(root.join(MESH_BUILDS));
        let tmp_dir = builds
            .create(&format!("case-{key}"), 0)
            .map_err(|e| OpenFoamError::io(builds.root(), e))?;
        let tmp = tmp_dir.to_path_buf();
        let built = CaseDir {
            dir: tmp.clone(),
            key: key.to_string(),
            project_dir: settings.project_dir.clone(),
        };
        built.build(g, settings)?;
        if dir.exists() && !dir.join(READY).is_file() {
            // A builder that died midway left it: replace it.
            std::fs::remove_dir_all(&dir).map_err(|e| OpenFoamError::io(&dir, e))?;
        }
        match std::fs::rename(&tmp, &dir) {
            Ok(()) => Ok(this),
            Err(_) if dir.join(READY).is_file() => {
                let _ = std::fs::remove_dir_all(&tmp);
                Ok(this)
            }
            Err(e) => Err(OpenFoamError::io(&dir, e)),
        }
    }

    /// The case directory.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// The key that names the case directory (`case-<key>`) and its runs (`runs-<key>`).
    pub fn key(&self) -> &str {
        &self.key
    }

    fn mesh_step(&self, step: &str, program: &str, extra: &[&str]) -> Result<(), OpenFoamError> {
        let mut args: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
        args.extend(case_arg(&self.dir));
        let (out, logs) = run_step(
            &self.dir,
            &self.project_dir,
            step,
            program,
            &args,
            Duration::from_secs(600),
        )?;
        let fail = |reason: String| OpenFoamError::Meshing {
            step: step.into(),
            reason,
            log_tail: log_tail(&logs, 20),
        };
        match out.end {
            ProcessEnd::Exited(0) => {}
            ProcessEnd::Exited(c) => return Err(fail(format!("exit code {c}"))),
            ProcessEnd::Signalled(s) => return Err(fail(format!("killed by signal {s}"))),
            ProcessEnd::TimedOut { .. } => return Err(fail("timed out after 600 s".into())),
        }
        let log = std::fs::read_to_string(logs.join("stdout.log")).unwrap_or_default();
        if !log.lines().any(|l| l.trim() == "End") {
            return Err(fail("no `End` in its log".into()));
        }
        Ok(())
    }

    fn build(&self, g: &CaseGeometry, st: &OpenFoamSettings) -> Result<(), OpenFoamError> {
        let d = &self.dir;
        write(&d.join("system/blockMeshDict"), &dicts::block_mesh(g))?;
        write(
            &d.join("system/topoSetDict.solid"),
            &dicts::topo_set_fluid(g),
        )?;
        write(
            &d.join("system/topoSetDict.patches"),
            &dicts::topo_set_patches(g),
        )?;
        write(&d.join("system/createPatchDict"), &dicts::create_patch(g))?;
        write(&d.join("system/controlDict"), &dicts::control_dict(g, st))?;
        write(&d.join("system/fvSchemes"), &dicts::fv_schemes())?;
        write(&d.join("system/fvSolution"), &dicts::fv_solution())?;
        write(
            &d.join("system/decomposeParDict"),
            &dicts::decompose_par(st.np),
        )?;
        self.mesh_step("blockMesh", "blockMesh", &[])?;
        self.mesh_step(
            "topoSet.solid",
            "topoSet",
            &["-dict", "system/topoSetDict.solid"],
        )?;
        self.mesh_step(
            "subsetMesh",
            "subsetMesh",
            &["fluid", "-patch", "walls", "-overwrite"],
        )?;
        self.mesh_step(
            "topoSet.patches",
            "topoSet",
            &["-dict", "system/topoSetDict.patches"],
        )?;
        self.mesh_step("createPatch", "createPatch", &["-overwrite"])?;
        let summary = self.check_mesh(g)?;
        // Fields and physics come after meshing: subsetMesh and createPatch rewrite 0/.
        for (name, text) in dicts::fields(g, st) {
            write(&d.join("0.orig").join(name), &text)?;
        }
        write(
            &d.join("constant/transportProperties"),
            &dicts::transport(st),
        )?;
        write(&d.join("constant/g"), &dicts::gravity())?;
        write(
            &d.join("constant/turbulenceProperties"),
            &dicts::turbulence(),
        )?;
        write(&d.join("constant/fvOptions"), &dicts::fv_options(g))?;
        let _ = std::fs::remove_dir_all(d.join("logs"));
        write(
            &d.join(READY),
            &format!(
                "cells {}\npatches {}\n",
                summary.cells,
                summary.patches.len()
            ),
        )
    }

    /// Reads `constant/polyMesh/boundary`, `owner` and `cellZones` and checks them against
    /// the geometry computed in Rust.
    fn check_mesh(&self, g: &CaseGeometry) -> Result<MeshSummary, OpenFoamError> {
        let mesh = self.dir.join("constant/polyMesh");
        let read = |f: &str| {
            let p = mesh.join(f);
            std::fs::read_to_string(&p).map_err(|e| OpenFoamError::io(&p, e))
        };
        let fail = |reason: String| OpenFoamError::Meshing {
            step: "check".into(),
            reason,
            log_tail: None,
        };
        let owner = read("owner")?;
        let cells = owner
            .split("nCells:")
            .nth(1)
            .and_then(|s| s.split_whitespace().next())
            .and_then(|s| s.parse::<usize>().ok())
            .ok_or_else(|| fail("no nCells in polyMesh/owner".into()))?;
        if cells != g.fluid_cells {
            return Err(fail(format!(
                "the mesh has {cells} cells, the hall's fluid has {}",
                g.fluid_cells
            )));
        }
        let boundary = read("boundary")?;
        let mut patches = Vec::new();
        for p in g.patches() {
            let faces = boundary
                .split(&format!("\n    {}\n", p.name))
                .nth(1)
                .and_then(|s| s.split("nFaces").nth(1))
                .and_then(|s| s.split(';').next())
                .and_then(|s| s.trim().parse::<usize>().ok())
                .ok_or_else(|| fail(format!("patch `{}` missing from the mesh", p.name)))?;
            if faces != p.faces {
                return Err(fail(format!(
                    "patch `{}` has {faces} faces, expected {}",
                    p.name, p.faces
                )));
            }
            patches.push((p.name.clone(), faces));
        }
        let zones = read("cellZones")?;
        let names = (0..g.servers.len())
            .map(|i| format!("heat{i}"))
            .chain(g.panel_zones.iter().map(|z| z.name.clone()));
        for name in names {
            if !zones.contains(&format!("{name}\n")) {
                return Err(fail(format!("cell zone `{name}` missing")));
            }
        }
        Ok(MeshSummary { cells, patches })
    }
}

/// Removes the run directories of solves killed mid-run (a calibration or diagnosis
/// stopped with `kill -9`) under every model's runs directory (`runs-*`) in `cache_root`,
/// and the half-meshed cases of builders killed midway (`mesh-builds`), and returns them
/// ([`kalibre_core::external::RunDirs::remove_interrupted`]); live solves and builds, of
/// this process or another, and kept failed ones stay. A missing root has none.
pub fn remove_interrupted_runs(cache_root: &Path) -> std::io::Result<Vec<PathBuf>> {
    let entries = match std::fs::read_dir(cache_root) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e),
    };
    let mut removed = Vec::new();
    for entry in entries {
        let entry = entry?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if (name.starts_with("runs-") || name == MESH_BUILDS) && entry.path().is_dir() {
            removed.extend(RunDirs::new(entry.path()).remove_interrupted()?);
        }
    }
    removed.sort();
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_killed_builders_half_meshed_case_is_swept_and_a_live_ones_is_not() {
        let root = std::env::temp_dir().join(format!("kalibre-mesh-sweep-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let builds = RunDirs::new(root.join(MESH_BUILDS));
        let live = builds.create("case-abc", 0).unwrap();
        // What a builder killed mid-mesh leaves: its directory and an unlocked marker.
        let killed = builds.root().join("case-abc-0000000000000000-9");
        std::fs::create_dir_all(killed.join("constant/polyMesh")).unwrap();
        std::fs::write(
            builds.root().join(".case-abc-0000000000000000-9.running"),
            "",
        )
        .unwrap();
        // A finished case beside them is never touched.
        let case = root.join("case-abc");
        std::fs::create_dir_all(&case).unwrap();
        std::fs::write(case.join(READY), "").unwrap();

        assert_eq!(
            remove_interrupted_runs(&root).unwrap(),
            vec![killed.clone()]
        );
        assert!(!killed.exists());
        assert!(live.is_dir(), "a build under way stays");
        assert!(case.join(READY).is_file());
        drop(live);
        std::fs::remove_dir_all(&root).unwrap();
    }
}
