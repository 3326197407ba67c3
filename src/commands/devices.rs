//! `splatraj devices [--json]`: what this machine can compute on: the CPU's threads (flex,
//! ndarray) and wgpu's adapters, each with the `CUBECL_WGPU_DEFAULT_DEVICE` value that picks
//! it, marking the one `backend = "wgpu"` takes. The listing is the library's
//! ([`splatraj::render::adapters::wgpu_adapters`], which starts no device); this file prints it.
//!
//! Exit status 1 when `CUBECL_WGPU_DEFAULT_DEVICE` is set and picks no adapter listed (a run
//! with `backend = "wgpu"` would then fail to start); 0 otherwise, also without wgpu.

use anyhow::{Result, bail};
use clap::Args;
use serde::Serialize;
use splatraj::render::adapters::{AdapterListing, Choice, SELECTOR_VARIABLE, wgpu_adapters};
use splatraj::render::backend::Hardware;

/// Arguments of `splatraj devices`.
#[derive(Debug, Args)]
pub struct DevicesArgs {
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

/// What `--json` prints.
#[derive(Debug, Serialize)]
struct Listing {
    /// rayon's threads: what flex and ndarray compute on.
    cpu_threads: usize,
    /// wgpu's adapters, where this build has wgpu.
    wgpu: Option<AdapterListing>,
    /// Why there is no listing, where there is none.
    wgpu_unavailable: Option<String>,
}

/// Runs `splatraj devices`.
pub fn run(args: DevicesArgs) -> Result<()> {
    let variable = std::env::var(SELECTOR_VARIABLE).ok();
    let (wgpu, wgpu_unavailable) = match wgpu_adapters(variable.as_deref()) {
        Ok(listing) => (Some(listing), None),
        Err(why) => (None, Some(why.to_string())),
    };
    let listing = Listing {
        cpu_threads: rayon::current_num_threads(),
        wgpu,
        wgpu_unavailable,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&listing)?);
    } else {
        print_table(&listing);
    }
    if let (Some(wgpu), Some(value)) = (&listing.wgpu, &variable)
        && wgpu.taken.is_none()
    {
        bail!(
            "{SELECTOR_VARIABLE}={value} picks no adapter listed here, so backend \"wgpu\" \
             cannot start; set it to one of the values listed, or unset it"
        );
    }
    Ok(())
}

fn print_table(listing: &Listing) {
    println!(
        "CPU (backend \"flex\" or \"ndarray\"): {} threads (RAYON_NUM_THREADS sets them)",
        listing.cpu_threads
    );
    let Some(wgpu) = &listing.wgpu else {
        if let Some(why) = &listing.wgpu_unavailable {
            println!("wgpu: {why}");
        }
        return;
    };
    if wgpu.adapters.is_empty() {
        println!(
            "wgpu on {}: no adapter. Install the GPU's Vulkan driver (NVIDIA: the driver's \
             Vulkan ICD; AMD and Intel: mesa-vulkan-drivers)",
            wgpu.api
        );
        return;
    }
    println!("wgpu on {}:", wgpu.api);
    let header = [
        SELECTOR_VARIABLE.to_string(),
        "type".into(),
        "name".into(),
        "driver".into(),
        "PCI bus".into(),
    ];
    let rows: Vec<[String; 5]> = wgpu
        .adapters
        .iter()
        .map(|a| {
            [
                a.selector.to_string(),
                a.kind.describe().into(),
                a.name.clone(),
                a.driver.clone(),
                a.pci_bus.clone(),
            ]
        })
        .collect();
    let widths: Vec<usize> = (0..header.len())
        .map(|c| {
            rows.iter()
                .map(|r| r[c].chars().count())
                .chain([header[c].len()])
                .max()
                .unwrap_or(0)
        })
        .collect();
    let line = |mark: &str, cells: &[String; 5]| {
        let padded: Vec<String> = cells
            .iter()
            .zip(&widths)
            .map(|(cell, &w)| format!("{cell:w$}"))
            .collect();
        println!("{mark} {}", padded.join("  ").trim_end());
    };
    line(" ", &header);
    for (i, row) in rows.iter().enumerate() {
        line(if wgpu.taken == Some(i) { "*" } else { " " }, row);
    }
    match (&wgpu.choice, wgpu.taken()) {
        (Choice::Default, Some(_)) => println!(
            "* backend \"wgpu\" runs here ({SELECTOR_VARIABLE} unset: wgpu's high-performance \
             adapter). Another: {SELECTOR_VARIABLE}=<value above>"
        ),
        (Choice::Default, None) => println!(
            "wgpu offers no high-performance adapter: set {SELECTOR_VARIABLE} to a value above"
        ),
        (Choice::Variable(value), Some(_)) => {
            println!("* backend \"wgpu\" runs here ({SELECTOR_VARIABLE}={value})")
        }
        // The caller ends with the error.
        (Choice::Variable(_), None) => {}
    }
    if let Some(adapter) = wgpu.taken()
        && adapter.kind == splatraj::render::adapters::AdapterKind::Cpu
        && let Some(warning) = (Hardware::EmulatedGpu {
            name: adapter.name.clone(),
        })
        .warning()
    {
        println!("warning: {warning}");
    }
}
