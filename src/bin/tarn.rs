//! The `tarn` command line: parses, calls the library, prints.

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "tarn",
    version,
    about = "Terrain maps and water hazards for off-road vehicles"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        None => Ok(()),
        Some(c) => match c {},
    }
}
