//! What one evaluated draw of the `optimized` sampler reports to the records it used: the
//! sample the optimiser's history keeps ([`super::history`]) and its Newton step reads
//! ([`super::optimize`]).

use super::search::Neighbours;
use super::{MAX_NEIGHBOURS, TECHNIQUES};
use filtrace_core::{luminance, Rgb};

/// What one evaluated draw of the `optimized` sampler teaches the records it used.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SampleFeedback {
    ids: [u32; MAX_NEIGHBOURS],
    weights: [f32; MAX_NEIGHBOURS],
    len: u8,
    /// `P_k(j)`.
    pub pmf: [f32; TECHNIQUES],
    /// `Q_k(j)`.
    pub cv: [f32; TECHNIQUES],
    /// `1 / q0(j)`, the sample's importance weight (1 for an exhaustive sum).
    pub inv_pdf: f32,
    /// Luminance of the full contribution f(j).
    pub value: f32,
}

impl SampleFeedback {
    /// Feedback for the records of `nb`.
    pub fn new(
        nb: &Neighbours,
        pmf: [f32; TECHNIQUES],
        cv: [f32; TECHNIQUES],
        inv_pdf: f32,
        contribution: Rgb,
    ) -> Self {
        let mut fb =
            SampleFeedback { pmf, cv, inv_pdf, value: luminance(contribution), ..Default::default() };
        for (s, (l, w)) in nb.iter().enumerate() {
            fb.ids[s] = l as u32;
            fb.weights[s] = w;
        }
        fb.len = nb.len() as u8;
        fb
    }

    /// Feedback for explicit `(record, weight)` pairs (synthetic problems, tests).
    pub fn for_records(
        records: &[(usize, f32)],
        pmf: [f32; TECHNIQUES],
        cv: [f32; TECHNIQUES],
        inv_pdf: f32,
        value: f32,
    ) -> Self {
        let mut fb = SampleFeedback { pmf, cv, inv_pdf, value, ..Default::default() };
        for (s, &(l, w)) in records.iter().take(MAX_NEIGHBOURS).enumerate() {
            fb.ids[s] = l as u32;
            fb.weights[s] = w;
        }
        fb.len = records.len().min(MAX_NEIGHBOURS) as u8;
        fb
    }

    /// `(record, weight)` pairs.
    pub fn records(&self) -> impl Iterator<Item = (usize, f32)> + '_ {
        let len = (self.len as usize).min(MAX_NEIGHBOURS);
        self.ids[..len].iter().zip(&self.weights[..len]).map(|(&l, &w)| (l as usize, w))
    }
}
