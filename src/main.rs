//! slosh: a thin binary over the library crates. Flags are parsed in `cli`, validated into
//! settings in `config`, and each subcommand lives in its own module.

mod bake;
mod cli;
mod config;
mod cpu;
mod generate;
mod info;
mod inspect;
mod machine;
mod play;
mod render;

use anyhow::Result;
use clap::Parser;
use slosh_bench::report::Report;
use slosh_fileio::say;

use crate::cli::{Cli, Command};

/// The longest the binary waits at exit for its GPU threads: one load in hand, which gives
/// up at its next piece, or a staging warm-up.
const BACKGROUND_GRACE: std::time::Duration = std::time::Duration::from_secs(10);

fn main() -> std::process::ExitCode {
    // Before anything else runs code built for the processor's newer instructions.
    let missing = cpu::missing_features();
    if !missing.is_empty() {
        eprintln!(
            "error: this slosh was built for x86-64-v3 processors, and this one lacks {}; \
             build it for this one with RUSTFLAGS=\"-C target-cpu=native\" cargo build --release",
            missing.join(", ")
        );
        return std::process::ExitCode::FAILURE;
    }
    run_checked()
}

/// [`main`] once the processor has what the build needs (kept out of `main`, whose code
/// runs before the check).
#[inline(never)]
fn run_checked() -> std::process::ExitCode {
    machine::keep_freed_memory();
    let result = run(Cli::parse());
    // Threads still using the GPU (loaders, a staging warm-up) end before the process does:
    // a driver torn down under them at exit can crash it.
    slosh_render::wait_for_background(BACKGROUND_GRACE);
    // Output that could not be written is an error too, once the work is done.
    let result = result.and_then(|()| match slosh_fileio::stdout::stdout_error() {
        Some(e) => Err(anyhow::anyhow!("writing to stdout: {e}")),
        None => Ok(()),
    });
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", message(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

/// The error and its causes, each said once: library errors already name their cause in
/// their own text ("path: No such file …"), so a cause whose text is there is not repeated.
fn message(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

fn run_bench(command: cli::BenchCommand) -> Result<()> {
    use cli::BenchCommand;
    use config::bench;
    use slosh_bench::{bake, gpu, precision, scrub};
    match command {
        BenchCommand::Accuracy(a) => accuracy(&bench::accuracy(&a)),
        BenchCommand::Bake(a) => {
            let settings = bench::bake(&a);
            written(&settings.out, &bake::run(&settings)?, false)
        }
        BenchCommand::Precision(a) => {
            let settings = bench::precision(&a);
            written(&settings.out, &precision::run(&settings)?, false)
        }
        BenchCommand::Gpu(a) => {
            let settings = bench::gpu(&a)?;
            written(&settings.out, &gpu::run(&settings)?, true)
        }
        BenchCommand::Scrub(a) => {
            let settings = bench::scrub(&a)?;
            // The raw case on the GPU measures the player as it plays one.
            if settings.raw_case && settings.raw_case_gpu {
                machine::keep_freed_pages()
                    .map_err(|e| anyhow::anyhow!("--raw-case-gpu: keeping freed memory: {e}"))?;
            }
            written(&settings.out, &scrub::run(&settings)?, true)
        }
    }
}

/// Writes a benchmark's report to `out`, then prints it (`echo`) or says where it went.
fn written(out: &std::path::Path, report: &impl Report, echo: bool) -> Result<()> {
    slosh_bench::report::write(out, report)?;
    if echo {
        slosh_fileio::stdout::say_text(&report.markdown());
    } else {
        say!("wrote {}", out.display());
    }
    Ok(())
}

/// `slosh bench accuracy`: the report, its JSON and plot where asked, or the SPH fixture.
fn accuracy(settings: &slosh_bench::accuracy::Settings) -> Result<()> {
    use slosh_bench::accuracy::Accuracy;
    use slosh_bench::report::{write, write_bytes};
    let json = |value: serde_json::Value| -> Result<()> {
        match &settings.json {
            Some(path) => write_bytes(path, serde_json::to_string_pretty(&value)?.as_bytes()),
            None => Ok(()),
        }
    };
    match slosh_bench::accuracy::run(settings)? {
        Accuracy::Fixture(dir) => say!("wrote the fixture under {}", dir.display()),
        Accuracy::SphOnly(report) => {
            write(&settings.out, &report)?;
            json(report.json())?;
            say!("wrote {}", settings.out.display());
        }
        Accuracy::Full(report) => {
            write(&settings.out, &report)?;
            json(report.json())?;
            report.write_plot(&settings.plot)?;
            say!(
                "wrote {} and {}",
                settings.out.display(),
                settings.plot.display()
            );
        }
    }
    Ok(())
}

pub(crate) fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Gen(args) => generate::run(&config::GenConfig::from_args(&args)?),
        Command::Bench(bench) => run_bench(bench),
        Command::Bake(args) if args.manifest_only => bake::manifest_only(&args.input),
        Command::Bake(args) => bake::run(&config::BakeConfig::from_args(&args)?),
        Command::Inspect(args) => inspect::run(&config::inspect::InspectConfig::from_args(&args)?),
        Command::Render(args) => {
            let mut config = config::render::RenderConfig::from_args(&args)?;
            let (mut unbaked, mut asked) = (Vec::new(), 0);
            if args.path.is_file() && args.path.extension().is_some_and(|e| e == "case") {
                let (dir, failed) = render::bake_case(&args, &config.steps)?;
                // A movie with frames missing would pass for whole: it is not made.
                if !failed.is_empty() && config.movie.is_some() {
                    anyhow::bail!(
                        "{} of {} steps did not bake (steps {failed:?}); no movie was made",
                        failed.len(),
                        config.steps.len()
                    );
                }
                config.path = dir;
                asked = config.steps.len();
                config.steps.retain(|s| !failed.contains(s));
                unbaked = failed;
            } else if args.cache.is_some() {
                anyhow::bail!(
                    "--cache: {} is not a .case file (--cache is where a case's steps are baked)",
                    args.path.display()
                );
            }
            render::with_unbaked(render::run(&config), &unbaked, asked)
        }
        Command::Play(args) => play::play(&args),
        Command::Demo(args) => play::demo(&config::demo::DemoConfig::from_args(&args)?),
        Command::Info(args) => {
            let mut case = slosh_ensight::Case::open(&args.case)?;
            case.set_byte_order(args.byte_order.map(Into::into));
            info::run(&case, args.json)
        }
    }
}
