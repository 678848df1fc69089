//! `ftcbf report`: the book's results pages from the stored JSON.

use std::path::PathBuf;

use ftcbf_lab::report;

/// Arguments of `ftcbf report`.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// Folder holding stamp.toml and the JSON files it lists (their paths are relative to the
    /// current directory, the repository root).
    #[arg(long, value_name = "DIR", default_value = "results")]
    pub results: PathBuf,
    /// Folder of the book's results pages.
    #[arg(long, value_name = "DIR", default_value = "book/src/results")]
    pub out: PathBuf,
    /// Write nothing; exit 1 when a page in --out differs from what the JSON gives.
    #[arg(long)]
    pub check: bool,
}

/// `ftcbf report`: load, render, then write or compare (the logic is `ftcbf_lab::report`).
pub fn command(a: &ReportArgs) -> anyhow::Result<()> {
    let inputs = report::load(&a.results)?;
    let pages = report::render(&inputs)?;
    if a.check {
        let differ = report::differences(&pages, &a.out)?;
        if !differ.is_empty() {
            let list: Vec<String> = differ.iter().map(|p| p.display().to_string()).collect();
            anyhow::bail!(
                "the results pages differ from what `{}` gives: {}; run `ftcbf report` and \
                 commit the pages",
                a.results.join(report::STAMP).display(),
                list.join(", ")
            );
        }
        println!(
            "{} pages and figures in {} are up to date",
            pages.len(),
            a.out.display()
        );
    } else {
        report::write(&pages, &a.out)?;
        println!(
            "wrote {} pages and figures to {}",
            pages.len(),
            a.out.display()
        );
    }
    Ok(())
}
