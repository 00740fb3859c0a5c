//! slosh: a thin binary over the library crates. Flags are parsed in `cli`, validated into
//! settings in `config`, and each subcommand lives in its own module.

mod bake;
mod cli;
mod config;
mod generate;
mod info;
mod inspect;
mod machine;
mod play;
mod render;

use anyhow::Result;
use clap::Parser;
use slosh_fileio::say;

use crate::cli::{Cli, Command};

fn main() -> std::process::ExitCode {
    machine::keep_freed_memory();
    let result = run(Cli::parse());
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
    match command {
        BenchCommand::Accuracy(a) => slosh_bench::accuracy::run(&bench::accuracy(&a)),
        BenchCommand::Bake(a) => slosh_bench::bake::run(&bench::bake(&a)),
        BenchCommand::Precision(a) => {
            let settings = bench::precision(&a);
            let report = slosh_bench::precision::run(&settings)?;
            slosh_bench::report::write(&settings.out, &report)?;
            say!("wrote {}", settings.out.display());
            Ok(())
        }
        BenchCommand::Gpu(a) => slosh_bench::gpu::run(&bench::gpu(&a)?),
        BenchCommand::Scrub(a) => slosh_bench::scrub::run(&bench::scrub(&a)?),
    }
}

pub(crate) fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Gen(args) => generate::run(&config::GenConfig::from_args(&args)?),
        Command::Bench(bench) => run_bench(bench),
        Command::Bake(args) if args.manifest_only => bake::manifest_only(&args.input),
        Command::Bake(args) => bake::run(&config::BakeConfig::from_args(&args)?),
        Command::Inspect(args) => inspect::run(&args),
        Command::Render(args) => render::run(&config::render::RenderConfig::from_args(&args)?),
        Command::Play(args) => play::play(&args),
        Command::Demo(args) => play::demo(&args),
        Command::Info(args) => {
            let mut case = slosh_ensight::Case::open(&args.case)?;
            case.set_byte_order(args.byte_order.map(Into::into));
            info::run(&case, args.json)
        }
    }
}
