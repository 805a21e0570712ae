#![no_main]
//! Reading a shard file never panics, and what it accepts is a possible shard of
//! a bounded run, which merging (alone, or twice over) never panics on.
use deformcal::app::protocol::{merge, parse_shard, MAX_SUBSETS};
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(file) = parse_shard(data, Path::new("/fuzz/shard-0-of-1.json")) else { return };
    assert!(file.shard[0] < file.shard[1], "shard {:?} accepted", file.shard);
    assert!((1..=MAX_SUBSETS).contains(&file.header.subsets));
    let _ = merge(vec![file.clone()]);
    let _ = merge(vec![file.clone(), file]);
});
