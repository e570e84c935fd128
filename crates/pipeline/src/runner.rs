//! The one setup of every command that runs the pipeline (`build`, `build --plan --shard`,
//! `plan`, `merge`): settings checked, thread count, memory plan, the output checked and
//! locked, the input opened, the work folder opened (resumed if it exists), the thread pool;
//! and the end of a run: the work folder removed on success ([`Runner::finish`]) or kept or
//! removed by the failure policy ([`Runner::fail`]).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use voxlod_ingest::MeshSource;

use crate::context::{BuildContext, Scope};
use crate::error::StageError;
use crate::files::output::{output_dir, OutputGuard, OutputKind};
use crate::files::work::{find_work_folders, WorkDir, WorkFolder};
use crate::memory::MemoryPlan;
use crate::settings::{check_settings, BuildSettings};
use crate::shard::plan_file::Fingerprint;
use crate::size::format_size;

/// What a run reads and writes.
pub(crate) enum Job<'a> {
    /// The stages over the mesh `input` in `scope`, writing `output` (the octree, a shard file
    /// or the plan), with a work folder.
    Mesh {
        /// The input mesh.
        input: &'a Path,
        /// The file written.
        output: &'a Path,
        /// What the run builds.
        scope: &'a Scope,
    },
    /// A merge: the octree `output` from the shard files `shards`; no input mesh, no work
    /// folder.
    Merge {
        /// The shard files read.
        shards: &'a [&'a Path],
        /// The octree file written.
        output: &'a Path,
    },
}

/// The input mesh of a run over one, and its work folder.
pub(crate) struct MeshRun {
    /// The input's path as given.
    pub input: PathBuf,
    /// The input, opened.
    pub source: MeshSource,
    /// The input's identity, taken before it was opened (for a plan).
    pub fingerprint: Option<Fingerprint>,
    /// The work folder.
    pub work: WorkDir,
    /// True if the work folder existed (the run resumes).
    pub resumed: bool,
    /// The work folder's parent (`--tmp`, else the output's folder).
    pub tmp_parent: PathBuf,
    /// What the run builds.
    pub scope: Scope,
}

/// A run, set up.
pub(crate) struct Runner {
    /// When the run started.
    pub t0: Instant,
    /// The settings.
    pub settings: BuildSettings,
    /// The output, checked and locked.
    pub guard: OutputGuard,
    /// The worker threads.
    pub pool: rayon::ThreadPool,
    /// How the memory budget is split.
    pub memory: MemoryPlan,
    /// Warnings so far (a thread count capped at the cores).
    pub warnings: Vec<String>,
    /// The input mesh and work folder (none for a merge).
    pub mesh: Option<MeshRun>,
}

impl Runner {
    /// Sets up `job` with the settings `s`; every check that can refuse the run comes before
    /// any work.
    pub(crate) fn open(job: Job, s: &BuildSettings) -> Result<Runner> {
        let t0 = Instant::now();
        check_settings(s)?;
        let mut warnings = Vec::new();
        let threads = thread_count(s.threads, &mut warnings);
        // a plan reports its warnings in its summary only
        let is_plan = matches!(
            job,
            Job::Mesh {
                scope: Scope::Plan,
                ..
            }
        );
        if s.progress && !is_plan {
            for w in &warnings {
                eprintln!("warning: {w}");
            }
        }
        let mut memory = MemoryPlan::new(s.memory, threads)?;
        // The output is checked (not a folder, not the input, not another kind of file,
        // writable folder with some space) and locked before any work starts.
        let (guard, mesh) = match job {
            Job::Mesh {
                input,
                output,
                scope,
            } => {
                let guard = OutputGuard::acquire(output, &[input], scope.output_kind(), s.force)?;
                let fingerprint = match scope {
                    Scope::Plan => Some(Fingerprint::of(input)?),
                    Scope::Whole | Scope::Shard(_) => None,
                };
                // the reader refuses what it cannot hold beside the least plan; what it holds
                // is planned for the whole build
                let mut opts = s.read_options();
                opts.memory = Some(memory.input_share());
                let source = MeshSource::open_with(input, &opts)?;
                memory = memory.with_input(source.info().held, threads)?;
                let tmp_parent = s.tmp_dir.as_deref().unwrap_or(output_dir(output));
                let key = WorkDir::key(input, s, scope.shard())?;
                let (work, resumed) = WorkDir::open(tmp_parent, output, &key)?;
                if s.progress && !is_plan {
                    eprintln!("{}", memory.describe());
                    if resumed {
                        eprintln!(
                            "resuming the interrupted build kept in {}",
                            work.path().display()
                        );
                    }
                }
                let mesh = MeshRun {
                    input: input.to_path_buf(),
                    source,
                    fingerprint,
                    work,
                    resumed,
                    tmp_parent: tmp_parent.to_path_buf(),
                    scope: scope.clone(),
                };
                (guard, Some(mesh))
            }
            Job::Merge { shards, output } => (
                OutputGuard::acquire(output, shards, OutputKind::Octree, s.force)?,
                None,
            ),
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .context("creating the thread pool")?;
        Ok(Runner {
            t0,
            settings: s.clone(),
            guard,
            pool,
            memory,
            warnings,
            mesh,
        })
    }

    /// The stages' shared context of a run over a mesh.
    pub(crate) fn context(&self) -> BuildContext<'_> {
        let mesh = self.mesh();
        BuildContext {
            settings: &self.settings,
            scope: &mesh.scope,
            source: &mesh.source,
            input: &mesh.input,
            output: &self.guard,
            pool: &self.pool,
            work: &mesh.work,
            memory: self.memory,
            progress: self.settings.progress,
            times: Vec::new(),
            warnings: self.warnings.clone(),
            interrupt: &crate::system::INTERRUPTED,
        }
    }

    /// The input mesh and work folder of a run over a mesh.
    pub(crate) fn mesh(&self) -> &MeshRun {
        self.mesh
            .as_ref()
            .expect("a run over a mesh has an input and a work folder")
    }

    /// Ends a run that succeeded: removes its work folder; after a build, adds to `warnings`
    /// the stale work folders of earlier runs beside it.
    pub(crate) fn finish(self, warnings: &mut Vec<String>) -> Result<()> {
        let Some(mesh) = self.mesh else {
            return Ok(());
        };
        mesh.work.remove()?;
        if !matches!(mesh.scope, Scope::Plan) {
            warn_stale_folders(&mesh.tmp_parent, warnings);
        }
        Ok(())
    }

    /// Ends a run that failed with `e`: the error to report, the work folder kept or removed
    /// by [`crate::failure::failed`].
    pub(crate) fn fail(self, e: StageError) -> anyhow::Error {
        match self.mesh {
            Some(mesh) => crate::failure::failed(e, mesh.work),
            None => e.into(),
        }
    }
}

/// Worker threads for `-j n` (0: one per core). More threads than cores never helps (every
/// stage is bound by the CPU or the disk), and thousands of them only thrash.
pub(crate) fn thread_count(asked: usize, warnings: &mut Vec<String>) -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if asked == 0 {
        cores
    } else if asked > cores {
        warnings.push(format!(
            "-j {asked}: capped at {cores}, the number of cores (more threads than cores only slow the build down)"
        ));
        cores
    } else {
        asked
    }
}

/// Warns of work folders of earlier builds that were killed and not resumed.
fn warn_stale_folders(tmp_parent: &Path, warnings: &mut Vec<String>) {
    let stale: Vec<_> = find_work_folders(tmp_parent)
        .unwrap_or_default()
        .into_iter()
        .filter(WorkFolder::is_stale)
        .collect();
    if stale.is_empty() {
        return;
    }
    let bytes = stale.iter().map(|f| f.bytes).sum();
    warnings.push(format!(
        "{} stale work folder{} of earlier interrupted builds ({}) in {}: `voxlod clean {}` lists and removes them",
        stale.len(),
        if stale.len() == 1 { "" } else { "s" },
        format_size(bytes),
        tmp_parent.display(),
        tmp_parent.display()
    ));
}
