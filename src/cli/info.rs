//! `gatetrace info`: what an output holds, from the file and its metadata (gatetrace::film::info).

use std::path::PathBuf;

use anyhow::Result;

#[derive(clap::Args)]
pub struct InfoArgs {
    /// An output of gatetrace render or merge: .npy, .exr or .png.
    file: PathBuf,
    /// Print everything as one JSON object (format, shape, layout, metadata) instead.
    #[arg(long)]
    json: bool,
}

/// `gatetrace info`: the file's description as text, or as one JSON object.
pub fn run(args: InfoArgs) -> Result<()> {
    let info = gatetrace::film::info::file_info(&args.file)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&info.to_json()).expect("JSON values"));
    } else {
        print!("{}", info.to_text(&args.file));
    }
    Ok(())
}
