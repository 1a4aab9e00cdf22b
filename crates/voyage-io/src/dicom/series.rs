//! The series choice: slices grouped by SeriesInstanceUID, the user's choice or the CT
//! series with the most slices, the others summarised.

use std::{collections::BTreeMap, path::Path};

use super::header::Header;
use crate::{LoadOptions, SeriesSummary};
use voyage_core::{Error, Result};
// ---------------------------------------------------------------------------------------------
// Series choice
// ---------------------------------------------------------------------------------------------

pub(super) type Choice = (Vec<Header>, Vec<SeriesSummary>, Option<String>);

/// Picks the series to load: the one the user named, else the CT series with the most slices
/// (ties broken by UID, so the choice is deterministic). Returns it, the others, and a note.
pub(super) fn choose_series(dir: &Path, images: Vec<Header>, opts: &LoadOptions) -> Result<Choice> {
    let mut groups: BTreeMap<String, Vec<Header>> = BTreeMap::new();
    for h in images {
        groups.entry(h.series_uid.clone()).or_default().push(h);
    }
    let summaries: Vec<SeriesSummary> = groups.iter().map(|(uid, hs)| summary(uid, hs)).collect();
    let chosen_uid = match &opts.series_uid {
        Some(want) => {
            if !groups.contains_key(want) {
                let list: Vec<String> = summaries.iter().map(describe_series).collect();
                return Err(Error::format(
                    dir,
                    format!(
                        "series {want} not found; the folder holds: {}",
                        list.join("; ")
                    ),
                ));
            }
            want.clone()
        }
        None => {
            let best = summaries
                .iter()
                .max_by_key(|s| (rank(s), std::cmp::Reverse(s.uid.clone())));
            best.map(|s| s.uid.clone()).unwrap_or_default()
        }
    };
    let others: Vec<SeriesSummary> = summaries
        .iter()
        .filter(|s| s.uid != chosen_uid)
        .cloned()
        .collect();
    let note = (!others.is_empty()).then(|| {
        let chosen = summaries.iter().find(|s| s.uid == chosen_uid);
        let tied: Vec<String> = others
            .iter()
            .filter(|o| chosen.is_some_and(|c| rank(o) == rank(c)))
            .map(describe_series)
            .collect();
        let mut how = match chosen {
            _ if opts.series_uid.is_some() => "as asked".to_string(),
            Some(s) if s.modality.as_deref() == Some("CT") => {
                "the CT series with the most slices".to_string()
            }
            _ => "no CT series; the series with the most slices".to_string(),
        };
        if opts.series_uid.is_none() && !tied.is_empty() {
            how += &format!(", tied with {} and taken by UID order", tied.join(" and "));
        }
        let chosen = chosen.map(describe_series).unwrap_or_default();
        format!(
            "the folder holds {} series; loaded {chosen}: {how}",
            summaries.len()
        )
    });
    let chosen = groups.remove(&chosen_uid).unwrap_or_default();
    Ok((chosen, others, note))
}

/// How a series ranks when none is asked for: CT first, then the most slices (a tie is
/// broken by UID, and named).
pub(super) fn rank(s: &SeriesSummary) -> (bool, usize) {
    (s.modality.as_deref() == Some("CT"), s.slices)
}

pub(super) fn summary(uid: &str, headers: &[Header]) -> SeriesSummary {
    SeriesSummary {
        uid: uid.to_string(),
        description: headers.iter().find_map(|h| h.series_description.clone()),
        modality: headers.iter().find_map(|h| h.modality.clone()),
        slices: headers.iter().map(|h| h.frames).sum(),
    }
}

pub(super) fn describe_series(s: &SeriesSummary) -> String {
    let uid = if s.uid.is_empty() {
        "(no SeriesInstanceUID)"
    } else {
        &s.uid
    };
    // No SeriesDescription: it is free text, and can hold a name (`info --show-descriptions`
    // lists them).
    format!(
        "{uid} ({}, {} slices)",
        s.modality.as_deref().unwrap_or("no modality"),
        s.slices
    )
}
