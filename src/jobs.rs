//! `vtfarm jobs`: the master's jobs, as a table or as JSON; a study is one
//! row, its variants' progress under it.

use anyhow::Result;
use vtfarm_master::http::JobRowView;

use crate::farm::ClusterArgs;
use crate::shared::runtime;

/// Options of `vtfarm jobs`.
#[derive(clap::Args)]
pub(crate) struct JobsArgs {
    #[command(flatten)]
    cluster: ClusterArgs,
    /// Also list the finished jobs the master keeps (completed, failed,
    /// cancelled).
    #[arg(long)]
    all: bool,
    /// One JSON array of the jobs instead of the table.
    #[arg(long)]
    json: bool,
}

/// `vtfarm jobs`.
pub(crate) fn jobs(args: JobsArgs) -> Result<()> {
    let options = args.cluster.client_options()?;
    let rows = runtime()?.block_on(vtfarm_submit::list_jobs(&options, args.all))?;
    if args.json {
        let rows: Vec<JobRowView> = rows.into_iter().map(JobRowView::from).collect();
        println!("{}", serde_json::to_string(&rows)?);
        return Ok(());
    }
    print!("{}", vtfarm_submit::listing::jobs_table(&rows));
    Ok(())
}
