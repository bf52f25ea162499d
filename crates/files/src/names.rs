//! Names closest to a wrong one, for the "did you mean" and "closest names" of messages.

/// Up to `n` of `candidates` closest to `name` by [`edit_distance`], closest first (for
/// "closest names" in messages).
pub fn closest<'a>(
    name: &str,
    candidates: impl IntoIterator<Item = &'a str>,
    n: usize,
) -> Vec<&'a str> {
    let mut scored: Vec<(usize, &str)> = candidates
        .into_iter()
        .map(|c| (edit_distance(name, c), c))
        .collect();
    scored.sort();
    scored.into_iter().take(n).map(|(_, s)| s).collect()
}

/// Edit distance, case-insensitive: insertions, deletions, substitutions and swaps of two
/// neighbouring characters (the commonest typo, `Fz_lr` for `Fz_rl`) cost one each (the
/// optimal string alignment distance).
pub fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.to_lowercase().chars().collect();
    let b: Vec<char> = b.to_lowercase().chars().collect();
    let mut before: Vec<usize> = Vec::new();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for i in 1..=a.len() {
        let mut cur = vec![i; b.len() + 1];
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            cur[j] = (prev[j] + 1).min(cur[j - 1] + 1).min(prev[j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                cur[j] = cur[j].min(before[j - 2] + 1);
            }
        }
        before = std::mem::replace(&mut prev, cur);
    }
    prev[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_swap_of_two_neighbours_costs_one_and_case_nothing() {
        assert_eq!(edit_distance("Fz_lr", "Fz_rl"), 1);
        assert_eq!(edit_distance("TIME", "time"), 0);
        assert_eq!(
            closest("GPS_Sped", ["v", "GPS_Speed", "a_x"], 1),
            ["GPS_Speed"]
        );
    }
}
