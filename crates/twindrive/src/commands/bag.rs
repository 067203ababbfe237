//! `twindrive bag`: looking into a rosbag2 recording.

use std::io::Write;

use crate::cli::BagCommand;

pub fn run(command: &BagCommand) -> anyhow::Result<()> {
    match command {
        BagCommand::Info { bag } => {
            let text = twindrive_calibrate::bag_info::describe(bag)?;
            std::io::stdout().lock().write_all(text.as_bytes())?;
            Ok(())
        }
    }
}
