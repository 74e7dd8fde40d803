//! Pieces every binary shares: robot selection, the one-line error exit, the git revision.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use nalgebra::Isometry3;

use selfmodel::core::error::Result;
pub use selfmodel::core::provenance::git_revision;
use selfmodel::sim::robot::Robot;
pub use selfmodel::sim::robots::{BuiltinRobot, shared_arm_urdf};
use selfmodel::sim::urdf_loader::{GeometryKind, pose_from_xyz_rpy};

/// A panic on a GPU's device thread (cubecl's `DSU-*` threads: a kernel that could not be
/// launched, a lost device) ends the process with one line and exit 1: the thread that waits
/// for that device would otherwise wait for ever.
fn end_on_device_failure() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let device_thread = std::thread::current()
                .name()
                .is_some_and(|n| n.starts_with("DSU-"));
            if !device_thread {
                return previous(info);
            }
            let msg = info
                .payload()
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| info.payload().downcast_ref::<String>().cloned())
                .unwrap_or_default();
            let msg = msg.split_whitespace().collect::<Vec<_>>().join(" ");
            eprintln!(
                "error: the GPU failed ({msg}); rerun with CUBECL_AUTOTUNE_LEVEL=minimal or a smaller --batch, and report it"
            );
            std::process::exit(1);
        }));
    });
}

/// The settings the library's messages name (in backticks, by its own names: `tips`), and the
/// flags that set them here.
const FLAGS: &[(&str, &str)] = &[
    ("cameras", "--cameras"),
    ("device", "--device"),
    ("eye", "--eye"),
    ("fov", "--fov"),
    ("geometry", "--geometry"),
    ("grid_step", "--grid-step"),
    ("group", "--group"),
    ("joints", "--joints"),
    ("margin", "--margin"),
    ("out", "--out"),
    ("precision", "--precision"),
    ("resume", "--resume"),
    ("sampler", "--sampler"),
    ("samples", "--samples"),
    ("protrusion_mm", "--protrusion-mm"),
    ("size", "--size"),
    ("spheres_per_link", "--spheres-per-link"),
    ("srdf", "--srdf"),
    ("target", "--target"),
    ("tip", "--tip"),
    ("tips", "--tips"),
    ("train", "--train"),
    ("urdf", "--urdf"),
    ("view", "--view"),
    ("where_close", "--where-close"),
];

/// A library message in the command line's terms: each setting it names in backticks
/// (`` `tips` ``) becomes the flag that sets it (`--tips`); anything else is left as it is.
pub fn in_flags(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    let mut rest = message;
    while let Some(open) = rest.find('`') {
        out.push_str(&rest[..open]);
        let after = &rest[open + 1..];
        let flag = after.find('`').and_then(|close| {
            let name = &after[..close];
            FLAGS
                .iter()
                .find(|(setting, _)| *setting == name)
                .map(|(_, flag)| (*flag, close))
        });
        match flag {
            Some((flag, close)) => {
                out.push_str(flag);
                rest = &after[close + 1..];
            }
            None => {
                out.push('`');
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
}

/// Run a binary's body: on error print one line (`error: <file>: <what>`, the library's
/// settings named by their flags: [`in_flags`]) and exit 1.
pub fn run_main(body: impl FnOnce() -> Result<()>) -> ExitCode {
    selfmodel::core::interrupt::install();
    end_on_device_failure();
    selfmodel::core::denormals::flush_everywhere();
    match body() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e @ selfmodel::Error::Interrupted(_)) => {
            eprintln!("interrupted: {}", in_flags(&e.to_string()));
            ExitCode::from(130)
        }
        Err(e) => {
            eprintln!("error: {}", in_flags(&e.to_string()));
            ExitCode::FAILURE
        }
    }
}

/// The whole `main` of an experiment binary: its `--help` text is the registry's description,
/// its options [`ExperimentArgs`], its default preset `default_preset`.
pub fn experiment_main(name: &'static str, default_preset: &str) -> ExitCode {
    use clap::{Args, Command, FromArgMatches};
    let about = crate::studies::registry::find(name).map_or("", |e| e.about);
    // After `augment_args`, which would set the about of `ExperimentArgs` itself.
    let command = ExperimentArgs::augment_args(Command::new(name))
        .about(about)
        .version(env!("CARGO_PKG_VERSION"))
        // `--steps -5` is a bad number, not an unknown option.
        .allow_negative_numbers(true);
    let args = match ExperimentArgs::from_arg_matches(&command.get_matches()) {
        Ok(args) => args,
        Err(e) => e.exit(),
    };
    // Before anything is written.
    git_revision();
    run_main(|| args.run(name, default_preset))
}

/// Three numbers on the command line: `x,y,z`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triple(pub [f64; 3]);

impl std::str::FromStr for Triple {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let v: Vec<f64> = s
            .split(',')
            .map(|p| {
                p.trim()
                    .parse::<f64>()
                    .map_err(|_| format!("\"{p}\" is not a number"))
            })
            .collect::<std::result::Result<_, _>>()?;
        match v[..] {
            [a, b, c] if v.iter().all(|x| x.is_finite()) => Ok(Triple([a, b, c])),
            _ => Err(format!("expected three finite numbers x,y,z, got \"{s}\"")),
        }
    }
}

impl std::fmt::Display for Triple {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{},{},{}", self.0[0], self.0[1], self.0[2])
    }
}

/// `--robot` / `--urdf` options.
#[derive(Clone, Debug, clap::Args)]
pub struct RobotArgs {
    /// Built-in robot (ignored when --urdf is given).
    #[arg(long, value_enum, default_value = "arm4")]
    pub robot: BuiltinRobot,
    /// Load the robot from a URDF instead (STL, COLLADA or OBJ meshes; `package://` resolved
    /// next to it).
    #[arg(long, value_name = "PATH")]
    pub urdf: Option<PathBuf>,
    /// Scene position of a URDF's root link, metres.
    #[arg(
        long,
        value_name = "X,Y,Z",
        default_value = "0,0,0",
        allow_hyphen_values = true
    )]
    pub base_xyz: Triple,
    /// Scene orientation of a URDF's root link, radians (fixed-axis roll, pitch, yaw).
    #[arg(
        long,
        value_name = "R,P,Y",
        default_value = "0,0,0",
        allow_hyphen_values = true
    )]
    pub base_rpy: Triple,
    /// Place a URDF as the papers' scene places arm4: base at [0,0,-0.108], yaw -pi/2.
    #[arg(long, conflicts_with_all = ["base_xyz", "base_rpy"])]
    pub arm4_scene: bool,
    #[command(flatten)]
    pub parts: UrdfParts,
}

/// How collision spheres are fitted: `--spheres-per-link` or `--protrusion-mm`.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct SphereFitArgs {
    /// Fit this many collision spheres to each link (clustered) [default: the fewest, up to
    /// 16, no wider than 1.25 times the link's half-width].
    #[arg(long, value_name = "N")]
    pub spheres_per_link: Option<usize>,
    /// Fit each link the fewest spheres (at most 256) whose outer surface stands at most MM
    /// millimetres outside it.
    #[arg(long, value_name = "MM", allow_hyphen_values = true)]
    pub protrusion_mm: Option<f64>,
    /// With --protrusion-mm: each point's spheres stand out at most half the least distance
    /// the links checked against it come to it, over 2,000 random collision-free
    /// configurations (fine where links come close, coarse elsewhere; at most 4,096 spheres a
    /// link).
    #[arg(long)]
    pub where_close: bool,
}

impl SphereFitArgs {
    /// The fit these flags ask for.
    pub fn fit(&self) -> Result<selfmodel::sim::collision::spheres::SphereFit> {
        selfmodel::sim::collision::spheres::SphereFit::with_budget(
            self.spheres_per_link,
            self.protrusion_mm,
            self.where_close,
        )
    }
}

/// `--tip`, `--geometry` and the joint group: what of a URDF's tree is the robot.
#[derive(Clone, Debug, clap::Args)]
pub struct UrdfParts {
    /// The URDF's end-effector link [default: the last link of its longest chain]. The joint
    /// vector is the chain from the root to it; movable joints off it are held (at 0, or the
    /// limit nearest 0), as in KDL and TRAC-IK chains.
    #[arg(long, value_name = "LINK", requires = "urdf")]
    pub tip: Option<String>,
    /// Which of the URDF's geometry the robot has (what is drawn and what a self-model sees).
    #[arg(long, value_enum, default_value = "visual", requires = "urdf")]
    pub geometry: GeometryKind,
    #[command(flatten)]
    pub group: JointGroupArgs,
}

/// `--joints` / `--tips`: which movable joints of a URDF's tree are the joint vector.
/// Each of them reads the URDF (`--urdf`).
#[derive(Clone, Debug, Default, clap::Args)]
#[group(requires = "urdf", multiple = true)]
pub struct JointGroupArgs {
    /// The joint vector: `all` (every movable joint of the tree) or joints by name
    /// (`--joints a,b,c`); the others are held (at 0, or the limit nearest 0). Joints are
    /// ordered depth-first from the root whatever order they are named in.
    #[arg(long, value_delimiter = ',', value_name = "all|NAMES")]
    pub joints: Option<Vec<String>>,
    /// The joint vector is the union of the chains from the root to these links (both hands
    /// of a humanoid, with the waist they share): `--tips left_hand,right_hand`.
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "LINKS",
        conflicts_with = "joints"
    )]
    pub tips: Option<Vec<String>>,
    /// The joint vector is a planning group of the robot's SRDF file (MoveIt's format: its
    /// joints, links, chains and subgroups; its chains' tip links are the tips): the one
    /// `.srdf` beside the URDF, in `../config/`, or in a `*_moveit_config` package beside it.
    #[arg(long, value_name = "NAME", conflicts_with_all = ["joints", "tips"])]
    pub group: Option<String>,
    /// The SRDF file `--group` reads [default: the one beside the URDF]; `ik train` also
    /// reads its <disable_collisions> for a collision check (without --group: for that
    /// alone).
    #[arg(long, value_name = "FILE")]
    pub srdf: Option<PathBuf>,
}

impl JointGroupArgs {
    /// The joint vector these switches name on the robot described at `urdf`.
    pub fn group(&self, urdf: Option<&Path>) -> Result<selfmodel::sim::kinematics::JointGroup> {
        selfmodel::sim::kinematics::JointGroup::from_args(
            self.joints.as_deref(),
            self.tips.as_deref(),
            self.group.as_deref(),
            self.srdf.as_deref(),
            urdf,
        )
    }
}

impl RobotArgs {
    /// The scene placement of a URDF robot.
    pub fn base(&self) -> Isometry3<f64> {
        if self.arm4_scene {
            return selfmodel::sim::arm4::scene_base();
        }
        pose_from_xyz_rpy(self.base_xyz.0, self.base_rpy.0)
    }

    /// Load the chosen robot.
    pub fn load(&self) -> Result<Robot> {
        self.spec()?.load()
    }

    /// The robot as a config records it.
    pub fn spec(&self) -> Result<selfmodel::sim::robots::RobotSpec> {
        Ok(match &self.urdf {
            Some(path) => {
                let base = self.base();
                let (r, p, y) = base.rotation.euler_angles();
                let t = base.translation.vector;
                selfmodel::sim::robots::RobotSpec::Urdf {
                    path: path.clone(),
                    base_xyz: [t.x, t.y, t.z],
                    base_rpy: [r, p, y],
                    tip: self.parts.tip.clone(),
                    geometry: self.parts.geometry,
                    joints: self.parts.group.group(Some(path))?,
                }
            }
            None => selfmodel::sim::robots::RobotSpec::Builtin(self.robot),
        })
    }

    /// A short name for reports: `arm4` or the URDF path.
    pub fn label(&self) -> String {
        match (&self.urdf, &self.parts.tip) {
            (Some(p), Some(t)) => format!("{} (tip {t})", p.display()),
            (Some(p), None) => p.display().to_string(),
            (None, _) => self.robot.name().into(),
        }
    }

    /// Whether the papers' camera sees this robot as it is (arm4, or a URDF in its scene);
    /// any other robot is framed automatically.
    pub fn papers_scene(&self) -> bool {
        self.arm4_scene || (self.urdf.is_none() && self.robot == BuiltinRobot::Arm4)
    }
}

/// The camera options of every binary that renders.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct CameraArgs {
    /// Camera position, metres (a fixed camera; with --target). Without it, a robot other than
    /// the papers' arm is framed automatically.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub eye: Option<Triple>,
    /// The point a fixed camera looks at, metres [default: the origin].
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub target: Option<Triple>,
    /// Vertical field of view, degrees.
    #[arg(long)]
    pub fov: Option<f64>,
    /// Image width and height in pixels.
    #[arg(long)]
    pub size: Option<usize>,
    /// Frame the robot automatically, looking from this direction (towards the camera from
    /// the robot) [default: 1,0.6,0.4, front right and a little above].
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true, conflicts_with_all = ["eye", "target"])]
    pub view: Option<Triple>,
}

impl CameraArgs {
    pub fn choice(&self) -> selfmodel::data::dataset::CameraChoice {
        selfmodel::data::dataset::CameraChoice {
            eye: self.eye.map(|t| t.0),
            target: self.target.map(|t| t.0),
            fov_deg: self.fov,
            size: self.size,
            view: self.view.map(|t| t.0),
        }
    }
}

/// The arguments every experiment binary shares.
#[derive(clap::Args, Debug, Clone)]
pub struct ExperimentArgs {
    /// paper (the papers' settings), short (the paper's data and models, training cut so all of
    /// table1 runs in under 5 minutes on a 2-core CPU) or quick (tiny, seconds).
    #[arg(long)]
    pub preset: Option<String>,
    /// Output folder [default: runs/<experiment>, git-ignored; the committed results were
    /// written with --out reports/<experiment>].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Where to train and run the models.
    #[arg(long, value_enum, default_value_t = selfmodel::core::device::DeviceChoice::Cpu)]
    pub device: selfmodel::core::device::DeviceChoice,
    /// Train and test on the paper-compatible dataset (its silhouettes include the ground
    /// plane below the horizon, as the paper's did), to compare with the paper's numbers.
    #[arg(long)]
    pub paper_compatible: bool,
    /// Continue from the checkpoints in the output folder.
    #[arg(long)]
    pub resume: bool,
    /// Train for this many steps instead of the preset's (the results say so).
    #[arg(long)]
    pub steps: Option<usize>,
    /// Self-models: images per training batch instead of the preset's (paper: 32 for NeuroKin);
    /// the learning rate is scaled by sqrt(B / preset's batch) and the steps by preset's batch /
    /// B, so the run covers the same epochs (`--steps` still sets the steps). For GPUs, whose
    /// throughput grows with the batch.
    #[arg(long, value_name = "B", conflicts_with = "reuse")]
    pub batch: Option<usize>,
    /// Self-models: train on the first N poses of a longer trajectory instead of the preset's
    /// (paper: 1,600); the test poses are the preset's count (400) that follow them (the
    /// results say so).
    #[arg(long, value_name = "N", conflicts_with = "dataset")]
    pub train_samples: Option<usize>,
    /// The robot: the arm of the inverse-kinematics experiments (emssl_*) [default: ur5], or
    /// the robot a self-model (neurokin, resneurokin_d, ...) learns [default: arm4].
    #[arg(long, value_enum)]
    pub robot: Option<BuiltinRobot>,
    /// Load the robot from a URDF instead (as ROS ships it: STL, COLLADA or OBJ meshes,
    /// `package://` paths; its root link at the origin unless --arm4-scene).
    #[arg(long, value_name = "PATH", conflicts_with = "robot")]
    pub urdf: Option<PathBuf>,
    /// Place the URDF as the papers' scene places arm4 (base at [0,0,-0.108], yaw -pi/2), so
    /// the papers' camera sees it.
    #[arg(long, requires = "urdf")]
    pub arm4_scene: bool,
    #[command(flatten)]
    pub parts: UrdfParts,
    #[command(flatten)]
    pub camera: CameraArgs,
    /// Self-models: train and test on this dataset (.npz as `dataset` writes it, or captured
    /// silhouettes in its format: `images` (N,H,W) uint8 0/255, `angles` (N,DOF) degrees
    /// (metres for prismatic joints), `focal` px, `poses` (N,4,4) camera-to-world; optional
    /// `depth` (N,H,W) metres, `n_train`) instead of rendering the robot. K-3DGS and FFKSM also
    /// need the robot that made it (--urdf, --tip).
    #[arg(long, value_name = "FILE.npz")]
    pub dataset: Option<PathBuf>,
    /// emssl_sampling_speed only: the forward model's per-call latencies to measure, instead
    /// of the preset's: none, sleep:US (waiting on a real arm) or spin:US (a CPU-bound
    /// simulator), comma-separated, e.g. `--latency none,spin:200`.
    #[arg(long, value_delimiter = ',', value_name = "LATENCY")]
    pub latency: Option<Vec<selfmodel::ik::paper::sampling_pass::Latency>>,
    /// table1 only: gather the rows the experiments wrote into their own folders under
    /// reports/ (same preset, dataset and steps) instead of training those models again.
    #[arg(long)]
    pub reuse: bool,
    /// table1: the self-models to train and compare (registry names, e.g.
    /// `neurokin,neurokin_tree,k3dgs,nearest_pose,mean_silhouette`) instead of every model of
    /// Table I; `neurokin_tree` is added only this way. ablation_data_scale: the self-models it
    /// scales (neurokin, link_splat, k3dgs) instead of NeuroKin.
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    pub models: Option<Vec<String>>,
    /// ablation_data_scale only: train on the first N poses for each N (e.g.
    /// `1600,3200,9600,25600,51200`), every size tested on the preset's test poses after the
    /// largest, instead of the paper's three sizes. With --models: the self-models to scale
    /// (neurokin, link_splat, k3dgs; default neurokin).
    #[arg(long, value_delimiter = ',', value_name = "N")]
    pub sizes: Option<Vec<usize>>,
    /// Self-models (neurokin, resneurokin_d): train the network in this dtype, as PyTorch's
    /// autocast (f32 master weights, Adam and losses; evaluated in f32). bf16 and f16 reach a
    /// GPU's tensor cores; flex32 (f32 stored, f16 computed) is a GPU dtype. The results'
    /// `precision` column says which.
    #[arg(long, value_enum, default_value_t = selfmodel::train::precision::Precision::F32)]
    pub precision: selfmodel::train::precision::Precision,
    /// Self-models: the learning rate along training: constant (the papers' protocol), or
    /// cosine (falling along a half cosine from the preset's rate to 1% of it at the last
    /// step, to train to a flat curve). The results' notes say which.
    #[arg(long, value_enum, default_value_t = selfmodel::train::config::LrSchedule::Constant)]
    pub schedule: selfmodel::train::config::LrSchedule,
}

impl ExperimentArgs {
    /// Refuse the options experiment `name` (`e`) does not take, and counts of zero, before
    /// anything runs.
    fn refuse_inapplicable(&self, name: &str, e: &crate::studies::run::Experiment) -> Result<()> {
        if self.models.is_some() && !["table1", "ablation_data_scale"].contains(&name) {
            return Err(selfmodel::Error::Config(format!(
                "--models applies to table1 and ablation_data_scale only, not {name}"
            )));
        }
        if self.sizes.is_some() && name != "ablation_data_scale" {
            return Err(selfmodel::Error::Config(format!(
                "--sizes applies to ablation_data_scale only, not {name}"
            )));
        }
        if self.sizes.as_ref().is_some_and(|s| s.contains(&0)) {
            return Err(selfmodel::Error::Config(
                "--sizes: each training-pose count must be at least 1".into(),
            ));
        }
        if let Some(models) = &self.models {
            if name == "table1" {
                crate::studies::table1::check_models(
                    models,
                    crate::studies::registry::EXPERIMENTS,
                )?;
            } else if let Some(m) = models
                .iter()
                .find(|m| !crate::studies::data_scale::MODELS.contains(&m.as_str()))
            {
                return Err(selfmodel::Error::Config(format!(
                    "--models {m}: ablation_data_scale trains {}",
                    crate::studies::data_scale::MODELS.join(", ")
                )));
            }
        }
        if self.reuse && name != "table1" {
            return Err(selfmodel::Error::Config(format!(
                "--reuse applies to table1 only, not {name}"
            )));
        }
        let camera_given =
            self.camera.choice() != selfmodel::data::dataset::CameraChoice::default();
        if (self.robot.is_some() || self.urdf.is_some() || camera_given || self.dataset.is_some())
            && !e.takes_robot
        {
            return Err(selfmodel::Error::Config(format!(
                "--robot, --urdf, --dataset and the camera options apply to the inverse-kinematics and self-model experiments, not {name}"
            )));
        }
        if let Some(file) = &self.dataset {
            if !file.exists() {
                return Err(selfmodel::Error::Config(format!(
                    "--dataset {}: no such file (make one with the dataset binary, or see its --help for the format)",
                    file.display()
                )));
            }
            // A FIFO, a device or a folder is refused for what it is, before any work.
            selfmodel::core::input_file::check_user_file(
                file,
                "dataset",
                selfmodel::core::input_file::MAX_TABLE_BYTES,
            )?;
        }
        if self.latency.is_some() && name != "emssl_sampling_speed" {
            return Err(selfmodel::Error::Config(format!(
                "--latency applies to emssl_sampling_speed only, not {name}"
            )));
        }
        if self.steps == Some(0) {
            return Err(selfmodel::Error::Config(
                "--steps must be at least 1".into(),
            ));
        }
        if self.batch == Some(0) {
            return Err(selfmodel::Error::Config(
                "--batch must be at least 1".into(),
            ));
        }
        if self.train_samples == Some(0) {
            return Err(selfmodel::Error::Config(
                "--train-samples must be at least 1".into(),
            ));
        }
        Ok(())
    }

    /// Run the registry's experiment `name` with these arguments and print its summary.
    pub fn run(&self, name: &str, default_preset: &str) -> Result<()> {
        let e = crate::studies::registry::find(name)?;
        let preset = self
            .preset
            .clone()
            .unwrap_or_else(|| default_preset.to_string());
        if !e.presets.contains(&preset.as_str()) {
            return Err(selfmodel::Error::Config(format!(
                "{name} has no preset \"{preset}\" (choose {})",
                e.presets.join(", ")
            )));
        }
        self.refuse_inapplicable(name, e)?;
        let opts = crate::studies::registry::RunOptions {
            preset,
            device: self.device,
            paper_compatible: self.paper_compatible,
            resume: self.resume,
            steps: self.steps,
            batch: self.batch,
            train_samples: self.train_samples,
            reuse_root: self.reuse.then(|| PathBuf::from(".")),
            robot: self.robot,
            urdf: self.urdf.clone(),
            arm4_scene: self.arm4_scene,
            tip: self.parts.tip.clone(),
            geometry: self.parts.geometry,
            joints: self.parts.group.group(self.urdf.as_deref())?,
            camera: self.camera.choice(),
            dataset: self.dataset.clone(),
            latencies: self.latency.clone(),
            models: self.models.clone(),
            sizes: self.sizes.clone(),
            precision: self.precision,
            schedule: self.schedule,
        };
        // Everything that can be checked is checked before the run writes its first file: the
        // device is compiled in, and a robot given by URDF loads and has a joint to move.
        opts.precision
            .check(&selfmodel::core::device::select(opts.device)?)?;
        if opts.urdf.is_some() {
            let spec = opts.robot_spec(selfmodel::sim::robots::BuiltinRobot::Arm4);
            spec.require_movable(&spec.load_kinematics()?, "a self-model or an inverse model")?;
        }
        // Another robot than the experiment's own writes under runs/robots/<robot>/.
        let own = if name.starts_with("emssl_") {
            selfmodel::sim::robots::BuiltinRobot::Ur5
        } else {
            selfmodel::sim::robots::BuiltinRobot::Arm4
        };
        let dir = self
            .out
            .clone()
            .unwrap_or_else(|| match opts.robot_folder(own) {
                Some(folder) => {
                    let default = e.dir_for(&opts.preset);
                    let leaf = default.file_name().map_or(name.into(), |f| f.to_owned());
                    folder.join(leaf)
                }
                None => e.dir_for(&opts.preset),
            });
        selfmodel::core::atomic_file::check_out(
            &dir,
            selfmodel::core::atomic_file::OutKind::Folder,
        )?;
        let start = std::time::Instant::now();
        let summary = e.run_in(&opts, &dir)?;
        let cpu = selfmodel::eval::compute_peak::machine_label(false);
        let done = format!(
            "{name} ({} preset): {:.0} s on {cpu}; wrote {}/{} (+ Markdown, figures)",
            opts.preset,
            start.elapsed().as_secs_f64(),
            dir.display(),
            tables_written(&dir)
        );
        println!("{summary}\n{done}");
        // What the command printed, for the README (which includes it, not a typed copy).
        selfmodel::core::atomic_file::write_bytes(
            &dir.join("console.txt"),
            format!("{summary}\n{done}\n").as_bytes(),
        )?;
        Ok(())
    }
}

/// The tables a run wrote into `dir` (each beside its Markdown), `results.csv` first, as the
/// run's last line names them: one name, or `{a.csv, b.csv}`.
fn tables_written(dir: &Path) -> String {
    let mut tables: Vec<String> = std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .flatten()
                .map(|e| e.file_name().to_string_lossy().to_string())
                .filter(|f| f.ends_with(".csv"))
                .collect()
        })
        .unwrap_or_default();
    tables.sort();
    if let Some(i) = tables.iter().position(|t| t == "results.csv") {
        let r = tables.remove(i);
        tables.insert(0, r);
    }
    match tables.len() {
        0 => String::new(),
        1 => tables.remove(0),
        _ => format!("{{{}}}", tables.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::in_flags;

    #[test]
    fn a_library_message_names_the_flags() {
        assert_eq!(
            in_flags("`tips`: \"x\" is not a link; give `group` or `joints`, not `both`"),
            "--tips: \"x\" is not a link; give --group or --joints, not `both`"
        );
        assert_eq!(in_flags("an unclosed `tip"), "an unclosed `tip");
        assert_eq!(in_flags("`grid_step` 0"), "--grid-step 0");
    }
}
