//! The `splatray` command line: its arguments and [`run`] (the library's
//! `run_cli`), which the binary's `main` calls with the process's arguments
//! and the Python package's `splatray` command (`splatray._splatray.main`)
//! calls with `sys.argv`.

use super::progress::ProgressLine;
use crate::Result;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use std::ffi::OsString;
use std::io::Write;

#[derive(Parser)]
#[command(
    name = "splatray",
    version,
    about = "Ray tracing point clouds as surface splats"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print splatray's version, the Embree version in use (asked from the
    /// device), the Embree library loaded and the thread count.
    Info,
    /// Render a scene (default: the bundled scenes/bunny.toml), or a point
    /// cloud with a scene made for it, to an image.
    Render(super::render::RenderArgs),
    /// Render a scene with every registered backend in one run and report
    /// each one's agreement with the first ray for ray, image for image,
    /// and their speeds and memory.
    Compare(super::compare::CompareArgs),
    /// Sample points from a triangle mesh (PLY): uniformly by area, or as a
    /// range scanner sees it from a viewpoint (--scan-from).
    Sample(super::sample_cmd::SampleArgs),
    /// Turn a point cloud into splats with Phong normal fields.
    Splat(super::splat_cmd::SplatArgs),
    /// Write splats as a Gaussian splat file (2DGS or 3DGS layout) that
    /// Gaussian renderers and trainers read.
    Export(super::export::ExportArgs),
    /// Vary the splat budget (epsilon) and the shading mode; measure splat
    /// generation, build and render seconds of every backend and the errors
    /// against the exact surface; write a CSV and a time-against-error plot
    /// (report §4.4, fig. 16).
    Sweep(super::sweep::SweepArgs),
    /// Check splats against the scan itself: hold out some points, splat the
    /// rest, and cast a ray from the scanner to every held-out point; report
    /// how many meet the splats at the point, early, late or not at all.
    ScanCheck(super::scan_check::ScanCheckArgs),
    /// Make a synthetic airborne survey: rolling terrain with buildings,
    /// scanned from above into georeferenced LAZ tiles (DIR/tiles/), with
    /// the exact surface as DIR/truth.ply; for scale runs.
    Terrain(TerrainArgs),
    /// Open a scene or point cloud in the browser, ray traced progressively
    /// as you orbit, pan and zoom (a local web server; prints its URL).
    View(super::viewer::ViewerArgs),
    /// Join the bands of one image (`render --band I/N`, rendered apart)
    /// top to bottom into the image a whole render writes.
    Stitch(StitchArgs),
}

/// Arguments of `splatray stitch`.
#[derive(clap::Args)]
struct StitchArgs {
    /// The bands, top to bottom (PNG or EXR, one width).
    #[arg(required = true, num_args = 1..)]
    parts: Vec<std::path::PathBuf>,
    /// The image (the parts' format).
    #[arg(short, long)]
    output: std::path::PathBuf,
}

/// Arguments of `splatray terrain`.
#[derive(clap::Args)]
struct TerrainArgs {
    /// The folder to make (tiles/ and truth.ply in it).
    #[arg(short, long)]
    output: std::path::PathBuf,
    /// Side of the square survey, metres.
    #[arg(long, default_value_t = 200.0)]
    size: f64,
    /// Tiles per side.
    #[arg(long, default_value_t = 2)]
    tiles: u32,
    /// Points per square metre.
    #[arg(long, default_value_t = 10.0)]
    density: f64,
    /// Buildings.
    #[arg(long, default_value_t = 12)]
    buildings: u32,
    /// Range noise (standard deviation), metres.
    #[arg(long, default_value_t = 0.03)]
    noise: f64,
    /// Seed: the same seed makes the same survey.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The survey's south-west corner, X,Y,Z (e.g. UTM metres).
    #[arg(long, value_delimiter = ',', default_value = "500000,4000000,100")]
    origin: Vec<f64>,
    /// How the scanner's rays look at the ground (flying north): oblique
    /// (two line scanners ±30° across, pitched 14° forward and back, as
    /// RIEGL's VQ-1560i), palmer (an elliptical scanner, ±20° across and
    /// ±14° fore and aft, as RIEGL's VQ-840-G), cross (strips flown
    /// north-south and east-west, ±15°) or across (one line scanner, ±15°
    /// across the track only: walls facing north and south get no point;
    /// the default before issue 39)
    #[arg(long, default_value = "oblique", value_parser = crate::names::parse::<crate::terrain::ScanPattern>)]
    pattern: crate::terrain::ScanPattern,
}

fn terrain(a: &TerrainArgs) -> Result<()> {
    let [x, y, z] = a.origin[..] else {
        return Err("--origin needs three numbers, X,Y,Z".into());
    };
    let p = crate::terrain::TerrainParams {
        size: a.size,
        tiles: a.tiles,
        density: a.density,
        buildings: a.buildings,
        noise: a.noise,
        seed: a.seed,
        origin: glam::DVec3::new(x, y, z),
        pattern: a.pattern,
    };
    let line = ProgressLine::new();
    let r = crate::terrain::write_terrain(&p, &a.output, Some(&|s, f| line.update(s, f)));
    line.finish();
    let r = r?;
    println!(
        "{} points in {} LAZ tiles -> {}; truth {} ({} triangles)",
        r.points,
        r.tiles.len(),
        a.output.join("tiles").display(),
        r.truth.display(),
        r.triangles
    );
    Ok(())
}

fn stitch(a: &StitchArgs) -> Result<()> {
    crate::render::output::check_output_path(&a.output)?;
    let (w, h) = crate::render::output::stitch(&a.parts, &a.output)?;
    println!("{} bands -> {w}x{h} {}", a.parts.len(), a.output.display());
    Ok(())
}

fn info() -> Result<()> {
    let device = crate::embree::Device::new()?;
    let (a, b, c) = device.version();
    println!("splatray {}", env!("CARGO_PKG_VERSION"));
    println!("embree   {a}.{b}.{c} (reported by the device)");
    match crate::embree::Device::library_path() {
        Some(p) => println!("library  {}", p.display()),
        None => println!("library  (not found in /proc/self/maps)"),
    }
    println!(
        "found by {} ({})",
        env!("SPLATRAY_EMBREE_FOUND_BY"),
        env!("SPLATRAY_EMBREE_LIB_DIR")
    );
    let config = crate::embree::config_in_force();
    let cpu = crate::embree::cpu_isas();
    if config.is_empty() {
        println!(
            "config   none: Embree runs the widest ISA this CPU has ({}); set {} to choose",
            cpu.last().copied().unwrap_or("unknown"),
            crate::embree::CONFIG_VAR
        );
    } else {
        println!("config   {config} (from {})", crate::embree::CONFIG_VAR);
    }
    println!("cpu isas {}", cpu.join(" "));
    let paths: Vec<&str> = crate::simd::available().iter().map(|i| i.name()).collect();
    println!(
        "simd     {} (the octree's leaf filter; this CPU runs: {}; set {} to choose)",
        crate::config::current().simd,
        paths.join(" "),
        crate::simd::SIMD_VAR
    );
    match crate::memory::limit() {
        Some(b) => println!(
            "memory   {:.1} GB may be allocated ({})",
            b.bytes as f64 / 1e9,
            b.source
        ),
        None => println!("memory   no bound stated by this machine"),
    }
    println!("threads  {}", rayon::current_num_threads());
    // Stable, machine-readable lines (`key: a b c`) for scripts/test.sh,
    // which runs the suites again on each: Embree's kernel sets this CPU
    // runs that SPLATRAY_EMBREE_CONFIG can force, and the octree's SIMD
    // paths. tests/embree_isa.rs and tests/simd_paths.rs check them.
    let forcible: Vec<&str> = cpu
        .iter()
        .copied()
        .filter(|i| crate::embree::FORCIBLE_ISAS.contains(i))
        .collect();
    println!("embree-isas: {}", forcible.join(" "));
    println!("simd-paths: {}", paths.join(" "));
    Ok(())
}

/// A file-size limit (`ulimit -f`, `RLIMIT_FSIZE`) passed by a write sends
/// SIGXFSZ, whose default action kills the process without a word and
/// leaves the temporary file of the atomic writer behind. With a handler
/// installed the write fails with EFBIG instead, and the error path runs:
/// one line naming the file, the temporary removed. Tokio's signal
/// registry installs that handler in safe code (no `unsafe` outside the
/// Embree and SIMD modules) and keeps it for the life of the process; the
/// signal, once caught, is ignored. SIGXFSZ is 25 on Linux but for MIPS.
fn catch_file_size_signal() {
    #[cfg(all(
        target_os = "linux",
        not(any(target_arch = "mips", target_arch = "mips64"))
    ))]
    {
        const SIGXFSZ: i32 = 25;
        if let Ok(rt) = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .build()
        {
            let _entered = rt.enter();
            let _ = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::from_raw(SIGXFSZ));
        }
    }
}

/// Runs the command line `args` (the program's name first, as
/// `std::env::args_os` gives it) and returns the exit status: 0; 1 after
/// the command's one-line error on stderr; clap's status after its usage
/// error (2), help or version (0), printed as clap's `exit` prints them.
/// Nothing exits the process: the Python command returns the status.
pub fn run<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    // Every command reads a word starting with `-` and a digit as a
    // number (`--origin -3,0,0`, `--scan-from -1,2,3`), not as a flag.
    let cli = Cli::command()
        .mut_subcommands(|c| c.allow_negative_numbers(true))
        .try_get_matches_from(args)
        .and_then(|m| Cli::from_arg_matches(&m));
    let status = match cli {
        Ok(cli) => run_command(cli.command),
        Err(e) => {
            let _ = e.print();
            u8::try_from(e.exit_code()).unwrap_or(2)
        }
    };
    let _ = std::io::stdout().flush();
    status
}

fn run_command(command: Command) -> u8 {
    catch_file_size_signal();
    // The environment is read once, here: an unusable SPLATRAY_SIMD or
    // SPLATRAY_PACKETS is refused before any work.
    let result = crate::config::Config::from_env()
        .and_then(crate::config::Config::install)
        .map_err(crate::Error::from)
        .and_then(|()| match command {
            Command::Info => info(),
            Command::Render(args) => super::render::run(&args),
            Command::Compare(args) => super::compare::run(&args),
            Command::Sample(a) => super::sample_cmd::run(&a),
            Command::Splat(a) => super::splat_cmd::run(&a),
            Command::Export(a) => super::export::run(&a),
            Command::Sweep(a) => super::sweep::run(&a),
            Command::ScanCheck(a) => super::scan_check::run(&a),
            Command::Stitch(a) => stitch(&a),
            Command::View(a) => super::viewer::run(&a),
            Command::Terrain(a) => terrain(&a),
        });
    match result {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("splatray: {e}");
            1
        }
    }
}
