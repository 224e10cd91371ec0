//! The check that a slot's tones share one frequency scale. A sender's clock error moves
//! all six tones by one factor; another codec's tones that land near ours each sit off by
//! their own amount, so no single scale reads them all on their peaks.

use super::Decoder;
use crate::significance::hann_share_inside;
use crate::tones::{tone_frequency_hz, Frame, BASIC_COUNT, SENDER_COUNT, TONE_COUNT};

/// Least share of a present tone's excess at its own best frequency scale that it must
/// keep at the frame's scale (see [`Decoder::has_off_grid_tone`]): −1.5 dB, a tone about
/// 3 Hz off the frame's common scale at 128 ms windows. A real tone loses at most the
/// comb's step (about 0.3 dB), plus noise, which [`OFF_GRID_Z`] allows for.
const OFF_GRID_SHARE: f64 = 0.7;
/// Noise allowance of the off-grid test, in standard deviations of the tone's sum.
const OFF_GRID_Z: f64 = 4.0;
/// Per-window excess (20 dB) over its neighbourhood's level from which a tone's peak
/// frequency is trusted (see [`Decoder::peaks_disagree`]).
const PEAK_LOUD: f64 = 100.0;
/// Largest distance of a loud tone's peak from the frame's common scale, Hz. A real
/// frame's loud tones agree with one scale to a small fraction of this; another codec's
/// tones passing near ours are off by their own hertz or more.
const PEAK_TOLERANCE_HZ: f64 = 0.5;
/// Least present tones of a faint frame found at the comb's outermost scale that reads
/// at least as strongly there as one step in (see [`Decoder::has_off_grid_tone`]).
const EDGE_MIN_TONES: usize = 5;
/// Largest distance of one loud tone's peak from the common scale of the others on a
/// long message's second slot (see [`Decoder::peaks_disagree`]).
const PEAK_TOLERANCE_ONE_HZ: f64 = 1.5;
/// Share of the slot skipped before the frequency checks (see
/// [`Decoder::has_off_grid_tone`]).
const STEADY_FROM: f64 = 0.25;

impl Decoder {
    /// Whether a present tone of `frame` sits off the frame's common frequency scale: its
    /// excess at `scale` is below [`OFF_GRID_SHARE`] of its excess at its own best scale,
    /// by more than [`OFF_GRID_Z`] noise standard deviations. Another codec's tones that
    /// land near ours (its 600 + 50·j Hz grid passes 4–14 Hz from our tones 2–12 and
    /// 58–66) each sit off by their own amount. Loud foreign tones fail by far; at low SNR
    /// the noise allowance swallows the test, as it should (a weak signal's peak is not
    /// known that well). `second_slot`: the slot is a long message's second (see
    /// [`Decoder::peaks_disagree`]).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn has_off_grid_tone(
        &self,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        scale: usize,
        a: f64,
        b: f64,
        clear: bool,
        second_slot: bool,
    ) -> bool {
        let window_len = self.geometry.window_len as f64;
        let scales = self.geometry.scale_count();
        let tones: Vec<usize> = frame.tones().into_iter().filter(|&k| present[k]).collect();
        let mut sums = vec![[0.0f64; 6]; scales];
        let mut margins = [[0.0f64; 2]; 6];
        let mut count = 0usize;
        // On the steady part of the slot: in a hall its first windows also hold the
        // reverberant tail of whatever sounded before, possibly the same tones from a
        // sender whose clock is off by another amount.
        let a = a + STEADY_FROM * (b - a);
        for w in &self.history {
            if hann_share_inside(w.start as f64, window_len, a, b) >= 0.9 {
                for (j, row) in sums.iter_mut().enumerate() {
                    for (i, &k) in tones.iter().enumerate() {
                        row[i] += f64::from(w.r[j * TONE_COUNT + k]);
                    }
                }
                for (i, &k) in tones.iter().enumerate() {
                    margins[i][0] += f64::from(w.margin_r[k]);
                    margins[i][1] += f64::from(w.margin_r[TONE_COUNT + k]);
                }
                count += 1;
            }
        }
        if count == 0 {
            return false;
        }
        let n = count as f64;
        // At the comb's outermost scale, the frame's power still rising outward (by more
        // than the noise allows) puts its tones beyond the tolerated error, where nothing
        // tells them from another codec's tones passing near ours. A real sender inside
        // the tolerance peaks inside the comb.
        let last = scales - 1;
        if last > 0 && (scale == 0 || scale == last) {
            let inner = if scale == 0 { 1 } else { last - 1 };
            let edge: f64 = sums[scale].iter().sum();
            let next: f64 = sums[inner].iter().sum();
            if edge - next > OFF_GRID_Z * edge.sqrt() {
                self.note(a, || "off grid: rising at the comb's edge".to_string());
                return true;
            }
            // A faint frame with at most four of its six tones present, reading as strongly
            // at the edge as one step in or more: whether it peaks inside the comb or beyond
            // it the noise cannot tell. A frame that babble, music and whistles assembled in
            // a hall came out so (seed 919, 1698.93 s: four of six tones at 4.3 dB, scale
            // 1.0060, edge 257 against 247 inside). A real sender within ±0.5% peaks a
            // few scales in, and when noise puts it at the edge it has 5 of 6 tones
            // present nearly always (−13 dB white at ±0.5% and +0.55%: no loss).
            // The same for a frame whose two votes each rest on a faint tone beside a loud
            // one, however loud that one: its typical tone (the median of four) is then a
            // loud tone, and the frame passed for clear. Two loud tones of something else
            // at the comb's edge, each completed to a vote by a tone near the floor,
            // assembled a false message in 10 h of backgrounds (seed 37, row 37050, every
            // background dry, 1666.47 s: k0 at 33 and k10 at 56 per window, k24 at 2.7 and
            // k34 at 3.8, scale 0.9940).
            let faint_votes = super::bursts::votes_rest_on_faint_tones(
                &tones,
                |i| (sums[scale][i] - n) / n,
                super::bursts::FAINT_VOTE_TONE,
            );
            if (!clear || faint_votes) && tones.len() < EDGE_MIN_TONES && edge >= next {
                self.note(a, || {
                    format!("off grid: a faint frame peaking at the comb's edge ({edge:.0} over {next:.0})")
                });
                return true;
            }
        }
        // One scale must explain every tone: the one the frame was found at came from the
        // search's sums, which in a hall also hold the tail of what sounded before, and
        // may sit a bin off the slot's own common scale.
        let best: Vec<f64> = (0..tones.len())
            .map(|i| {
                sums.iter()
                    .map(|row| row[i])
                    .fold(f64::NEG_INFINITY, f64::max)
            })
            .collect();
        let misfits = |j: usize| -> Vec<usize> {
            (0..tones.len())
                .filter(|&i| {
                    sums[j][i] - n < OFF_GRID_SHARE * (best[i] - n) - OFF_GRID_Z * best[i].sqrt()
                })
                .collect()
        };
        // For a frame clear of the floor, one tone off the common scale is let go when the
        // vote of its basic holds without it: in a babble hall a tone in a notch of the
        // room sits at the talkers' level, and a harmonic beside it pulls its best scale
        // (lab and hall T60 1.2 s at 0 dB, tuning row 11024: k23 at 72 per window on the
        // frame's scale against 225 at its best while the other five fit). Another
        // codec's tones passing near ours are each off by their own amount: more than one.
        let fits = |j: usize| match misfits(j).as_slice() {
            [] => true,
            &[i] => clear && vote_holds_without(&tones, tones[i]),
            _ => false,
        };
        let on_grid = fits(scale) || (clear && (0..scales).any(fits));
        // Each tone's local background over the same windows: the median non-frame tone
        // within ±NEIGHBOURHOOD, over the noise mean (at least 1).
        let own = frame.tones();
        let locals: Vec<f64> = match self.integrate_slot(scale, a, b) {
            Some(slot) => tones
                .iter()
                .map(|&k| {
                    let around = super::confirm::neighbourhood(&own, k, &slot.sums);
                    (super::median(around) / slot.count.max(1) as f64).max(1.0)
                })
                .collect(),
            _ => vec![1.0; tones.len()],
        };
        if !on_grid {
            self.note(a, || {
                let lost: Vec<String> = (0..tones.len())
                    .map(|i| format!("k{} {:.0}/{:.0}", tones[i], sums[scale][i] - n, best[i] - n))
                    .collect();
                format!(
                    "off grid: no common scale (at the frame's / best) {}",
                    lost.join(" ")
                )
            });
            return true;
        }
        self.peaks_disagree(&tones, &sums, &margins, n, &locals, second_slot)
    }

    /// Whether the loud tones among `tones` (slot sums `sums[j][i]` at every scale `j` over
    /// `n` windows) peak at frequencies no single scale explains: each loud tone's peak is
    /// located between FFT bins (a parabola through the log excess of the loudest bin
    /// the comb reads for it and its two neighbours), the common scale fitted (weighted by
    /// frequency², as the Hz error is alike for every tone), and a tone more than
    /// [`PEAK_TOLERANCE_HZ`] from it fails. Only tones ≥ 20 dB per window above their
    /// neighbourhood (`locals[i]`, the median of the non-frame tones within ±3 over the
    /// noise mean, at least 1) count: their peak is known to a small fraction of a bin,
    /// and a foreign burst loud enough to pass for our frame is that loud. Where babble
    /// lifts the band around a tone (speech's formants, smeared by a hall), the floor is
    /// not what it competes with: a loud tone there still had its peak pulled by half a
    /// hertz to a hertz by the talkers' harmonics, and the frame was refused. One loud
    /// tone off the fit, or peaking beyond the comb, is let go when at least three others
    /// agree within the tolerance and its basic's vote holds on its other two tones; on a
    /// long message's `second_slot` one tone up to [`PEAK_TOLERANCE_ONE_HZ`] off is let go
    /// without that condition.
    fn peaks_disagree(
        &self,
        tones: &[usize],
        sums: &[[f64; 6]],
        margins: &[[f64; 2]; 6],
        n: f64,
        locals: &[f64],
        second_slot: bool,
    ) -> bool {
        let bin_hz = self.rate() / self.geometry.fft_len as f64;
        // Loud tones' peaks (tone, nominal Hz, measured Hz), and loud tones peaking beyond
        // the comb.
        let mut peaks: Vec<(usize, f64, f64)> = Vec::new();
        let mut beyond: Vec<usize> = Vec::new();
        for (i, &k) in tones.iter().enumerate() {
            let mut by_bin: Vec<(usize, f64)> = sums
                .iter()
                .enumerate()
                .map(|(j, row)| {
                    (
                        self.geometry.bins[j * TONE_COUNT + k],
                        (row[i] - n).max(1e-9),
                    )
                })
                .collect();
            by_bin.dedup_by_key(|x| x.0);
            // One bin beyond the comb on each side: a loud tone peaking there lies beyond
            // the tolerated error, even when the comb's last bin still reads it strongly.
            by_bin.insert(
                0,
                (self.geometry.margin_bins[k], (margins[i][0] - n).max(1e-9)),
            );
            by_bin.push((
                self.geometry.margin_bins[TONE_COUNT + k],
                (margins[i][1] - n).max(1e-9),
            ));
            let Some((p, _)) = by_bin
                .iter()
                .enumerate()
                .max_by(|x, y| x.1 .1.total_cmp(&y.1 .1))
            else {
                continue;
            };
            if by_bin[p].1 < PEAK_LOUD * n * locals[i] {
                continue;
            }
            if p == 0 || p + 1 >= by_bin.len() {
                beyond.push(k);
                continue;
            }
            if by_bin[p - 1].0 + 1 != by_bin[p].0 || by_bin[p].0 + 1 != by_bin[p + 1].0 {
                continue;
            }
            let (l, c, r) = (by_bin[p - 1].1.ln(), by_bin[p].1.ln(), by_bin[p + 1].1.ln());
            let den = l - 2.0 * c + r;
            if den >= 0.0 {
                continue;
            }
            let delta = (0.5 * (l - r) / den).clamp(-0.5, 0.5);
            peaks.push((
                k,
                tone_frequency_hz(k),
                (by_bin[p].0 as f64 + delta) * bin_hz,
            ));
        }
        // The common scale of `peaks` by least squares (f̂ = f · (1 + s): s = Σ f (f̂ − f)
        // / Σ f²), and the tone farthest from it: (its place, Hz off).
        let fit = |peaks: &[(usize, f64, f64)]| -> (usize, f64) {
            let s = peaks.iter().map(|(_, f, g)| f * (g - f)).sum::<f64>()
                / peaks.iter().map(|(_, f, _)| f * f).sum::<f64>();
            peaks
                .iter()
                .enumerate()
                .map(|(i, (_, f, g))| (i, (g - f * (1.0 + s)).abs()))
                .fold((0, 0.0), |m, x| if x.1 > m.1 { x } else { m })
        };
        // The one loud tone that may be let go: a tone beyond the comb, or else the one
        // farthest from the common scale of all.
        let (excused, rest, off) = match beyond.as_slice() {
            [] if peaks.len() < 3 => return false,
            [] => {
                let (wi, worst) = fit(&peaks);
                if worst <= PEAK_TOLERANCE_HZ {
                    return false;
                }
                let mut rest = peaks.clone();
                let (k, ..) = rest.remove(wi);
                (k, rest, worst)
            }
            &[k] => (k, peaks.clone(), f64::INFINITY),
            _ => {
                self.note(self.latest_window_end(), || {
                    format!("off grid: {beyond:?} peak beyond the comb")
                });
                return true;
            }
        };
        let rest_worst = if rest.len() >= 3 {
            fit(&rest).1
        } else {
            f64::INFINITY
        };
        // One loud tone pulled off (or past the comb's edge) while at least three others
        // agree within the tolerance: let go when the vote of its basic holds without it.
        // In a babble hall the lowest tones sit in the talkers' loudest band, and a
        // harmonic a bin or two beside a tone pulls its peak by 1.5-3 Hz or past the comb
        // (hall T60 1.2 s at 0 dB, tuning row 11024: 34 of 44 lost long messages refused
        // so, nearly all on k1 at 549 Hz while the other loud tones agreed within 0.25 Hz).
        // Another codec's tones passing near ours are off each by its own amount, not all
        // but one within half a hertz of one scale; and a frame assembled from two of our
        // robots (each clock off by its own amount) has a loud tone of each off the other's
        // scale, so the basic that loses its tone must still hold its vote on the others.
        // On a long message's second slot (sender and scale decided on the first), one
        // tone up to PEAK_TOLERANCE_ONE_HZ off is let go without that condition.
        // On a second slot two other loud tones agreeing with each other suffice: in a
        // T60 1.2 s lab at 0 dB a second frame has three loud tones as often as not, the
        // lowest (k1, 549 Hz) pulled 0.5-1.2 Hz by a talker while the other two agreed
        // within 0.1 Hz (tuning row 11021: 5 of 13 lost long messages).
        // And on a second slot a tone peaking beyond the comb, where its basic's vote holds
        // without it, is let go beside two loud tones that agree: the sender's scale is
        // the first slot's, and a talker's harmonic a bin or two beside a tone puts its
        // loudest bin past the comb's last (long lab-1.2 0 dB, tuning rows 82021–87021:
        // 7 of the 16 second slots refused as off grid, e.g. 70021 at 236.05 s: k18 past
        // the comb while k42 and k66 of its basic were present and two loud tones agreed
        // within 0.5 Hz).
        // On a first slot, two loud tones that agree are enough when one is the sender's
        // and the other the data's: the pair ties the two basics to one clock, which a
        // frame assembled from two robots (each clock off by its own amount) does not
        // show, and another codec's tones passing near ours are off each by its own
        // amount. Short lab T60 1.2 s 0 dB, tuning draws S = 111–122: 18 of the 86 lost
        // short messages were refused off grid, nearly all on k1 (549 Hz, pulled by a
        // talker or past the comb) with two other loud tones left; in 11 of them a
        // sender tone and a data tone agreed within 0.3 Hz (114015 at 911.92 s: k29 and
        // k49 at −0.268% and −0.264%, k1 past the comb).
        let vote_holds = vote_holds_without(tones, excused);
        let pair_fits = rest.len() == 2 && fit(&rest).1 <= PEAK_TOLERANCE_HZ;
        let is_sender = |k: usize| k % BASIC_COUNT < SENDER_COUNT;
        let mixed_pair =
            !second_slot && pair_fits && is_sender(rest[0].0) != is_sender(rest[1].0) && vote_holds;
        let pair_agrees = second_slot && pair_fits;
        let beyond_let_go = off.is_infinite() && vote_holds;
        let let_go = (rest_worst <= PEAK_TOLERANCE_HZ
            && (vote_holds || (second_slot && off <= PEAK_TOLERANCE_ONE_HZ && rest.len() >= 3)))
            || (pair_agrees && (off <= PEAK_TOLERANCE_ONE_HZ || beyond_let_go))
            || mixed_pair;
        self.note(self.latest_window_end(), || {
            let r: Vec<String> = peaks
                .iter()
                .map(|(_, f, g)| format!("{f:.0}:{:+.2}", g - f))
                .collect();
            format!(
                "peaks: k{excused} off {off:.2} Hz (beyond the comb: {}), the rest within {rest_worst:.2} [{}]: {}",
                beyond.len(),
                r.join(" "),
                if let_go { "let go" } else { "off grid" }
            )
        });
        !let_go
    }
}

/// Whether the basic of tone `k` keeps two tones among the frame's present `tones` other
/// than `k` (its 2-of-3 vote holds without it).
fn vote_holds_without(tones: &[usize], k: usize) -> bool {
    let basic = k % crate::tones::BASIC_COUNT;
    tones
        .iter()
        .filter(|&&t| t != k && t % crate::tones::BASIC_COUNT == basic)
        .count()
        >= 2
}
