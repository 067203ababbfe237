//! Decodes every message of every topic of a rosbag2 recording with the
//! definitions stored in it, and prints the count and the time it took
//! (the twindrive side of `bench/rosbag_vs_rosbags.sh`).
//!
//! Usage: bag_decode BAG [REPEAT]

use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).ok_or("usage: bag_decode BAG [REPEAT]")?;
    let repeat: usize = args.get(2).map_or(Ok(3), |r| r.parse())?;
    let mut best = f64::INFINITY;
    let mut messages = 0u64;
    for _ in 0..repeat {
        let started = Instant::now();
        let bag = twindrive_ros::Bag::open(std::path::Path::new(path))?;
        let topics: Vec<&str> = bag.topics().iter().map(|t| t.name.as_str()).collect();
        let counts = bag.for_each_of(&topics, |_, m| {
            std::hint::black_box(m.value);
            Ok(())
        })?;
        messages = counts.iter().sum();
        best = best.min(started.elapsed().as_secs_f64());
    }
    println!("messages {messages}");
    println!("twindrive_decode_s {best:.4}");
    Ok(())
}
