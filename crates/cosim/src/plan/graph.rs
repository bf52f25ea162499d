//! Stage "order": the connection graph's direct feed-through cycles, and the stepping
//! order.

use super::instances::Units;
use super::problems::OrderError;
use super::{ConnectionDef, Endpoint, InstanceDef};
use crate::config::SystemFile;
use crate::split_name;
use std::collections::HashMap;
use tb_fmi::import::description::{ModelDescription, ScalarVariable, Unknown};
use tb_fmi::{Causality, VarKey};

/// A node of the feed-through graph: a connected input or output, as (instance, value
/// space and value reference).
type Node = (usize, VarKey);

/// The feed-through graph: from each node, the nodes it feeds directly, each edge marked
/// `true` when it is certain (a connection, or a dependency the FMU declares) and `false`
/// when only assumed (an output that declares no dependencies).
type Edges = HashMap<Node, Vec<(Node, bool)>>;

/// Direct feed-through cycles: output -> input (connection) -> output of the same instance
/// (declared dependency). Cycles made only of declared dependencies are errors; cycles
/// that rely on outputs without a `dependencies` attribute (meaning "may depend on every
/// input") are warnings.
pub(crate) fn check_feedthrough_cycles(
    instances: &[InstanceDef],
    connections: &[ConnectionDef],
    warnings: &mut Vec<String>,
) -> Result<(), OrderError> {
    let mut edges = connection_edges(connections);
    for (k, inst) in instances.iter().enumerate() {
        dependency_edges(k, inst, &mut edges);
    }
    let Some(cycle) = first_cycle(&edges) else {
        return Ok(());
    };
    // The cycle starts and ends at the same node.
    let text = cycle
        .iter()
        .map(|(n, _)| node_name(instances, n))
        .collect::<Vec<_>>();
    let text = text.join(" -> ");
    if cycle.iter().all(|c| c.1) {
        return Err(OrderError::AlgebraicLoop { cycle: text });
    }
    warnings.push(format!(
        "possible feed-through cycle through outputs that declare no dependencies: {text}"
    ));
    Ok(())
}

/// The connections' edges: an FMU output feeds the input it is connected to (a replayed
/// column is fed by nothing, so it is no part of a cycle).
fn connection_edges(connections: &[ConnectionDef]) -> Edges {
    let mut edges: Edges = HashMap::new();
    for c in connections {
        if let Endpoint::Fmu { unit, vr, ty, .. } = c.from {
            edges
                .entry((unit, (ty.value_space(), vr)))
                .or_default()
                .push(((c.to_unit, c.to_key()), true));
        }
    }
    edges
}

/// Instance `k`'s edges: each input feeds every output that depends on it.
fn dependency_edges(k: usize, inst: &InstanceDef, edges: &mut Edges) {
    let md = inst.description();
    // Every output: the ModelStructure's entry, or none (an output missing from it may
    // depend on every input, as one without a `dependencies` attribute). The entries by
    // index, once (a scan per output was quadratic, M11).
    let mut listed: HashMap<usize, &Unknown> = HashMap::with_capacity(md.outputs.len());
    for o in &md.outputs {
        listed.entry(o.index).or_insert(o);
    }
    let outputs = md
        .variables
        .iter()
        .enumerate()
        .filter(|(_, v)| v.causality == Causality::Output)
        .map(|(i, v)| (v, listed.get(&(i + 1)).copied()));
    for (out, o) in outputs {
        let (deps, declared) = output_dependencies(md, o);
        // An output that is an alias of an input is that input, not a loop through it.
        for inp in deps.into_iter().filter(|i| i.key() != out.key()) {
            edges
                .entry((k, inp.key()))
                .or_default()
                .push(((k, out.key()), declared));
        }
    }
}

/// The inputs an output (with its ModelStructure entry `o`, if any) depends on, and whether
/// the FMU declares them: its `dependencies`, else every input (assumed).
fn output_dependencies<'m>(
    md: &'m ModelDescription,
    o: Option<&Unknown>,
) -> (Vec<&'m ScalarVariable>, bool) {
    match o.and_then(|o| o.dependencies.as_ref()) {
        Some(d) => (
            d.iter()
                .filter_map(|i| md.variables.get(i - 1))
                .filter(|v| v.causality == Causality::Input)
                .collect(),
            true,
        ),
        None => (md.variables_of(Causality::Input).collect(), false),
    }
}

/// A node by its system name, `instance.variable` (`?` for a variable the instance does not
/// have).
fn node_name(instances: &[InstanceDef], n: &Node) -> String {
    let inst = &instances[n.0];
    let v = inst
        .description()
        .variables
        .iter()
        .find(|v| v.has_key(n.1))
        .map(|v| v.name.as_str())
        .unwrap_or("?");
    format!("{}.{v}", inst.name)
}

/// The first cycle of the graph, by a depth-first search from each node in order: its
/// edges from the node it starts at round to that node.
fn first_cycle(edges: &Edges) -> Option<Vec<(Node, bool)>> {
    let mut color: HashMap<Node, u8> = HashMap::new();
    let mut nodes: Vec<Node> = edges.keys().copied().collect();
    nodes.sort();
    for n in nodes {
        if color.get(&n).copied().unwrap_or(0) == 0 {
            let mut path = vec![(n, true)];
            if let Some(cycle) = dfs(n, edges, &mut color, &mut path) {
                return Some(cycle);
            }
        }
    }
    None
}

/// The depth-first search from `n` along `path`: the cycle it closes, if any. `color`
/// marks the nodes on the path (1) and those done (2).
fn dfs(
    n: Node,
    edges: &Edges,
    color: &mut HashMap<Node, u8>,
    path: &mut Vec<(Node, bool)>,
) -> Option<Vec<(Node, bool)>> {
    color.insert(n, 1);
    if let Some(next) = edges.get(&n) {
        for &(m, declared) in next {
            path.push((m, declared));
            match color.get(&m).copied().unwrap_or(0) {
                1 => {
                    let start = path.iter().position(|p| p.0 == m).unwrap_or(0);
                    return Some(path[start..].to_vec());
                }
                0 => {
                    if let Some(c) = dfs(m, edges, color, path) {
                        return Some(c);
                    }
                }
                _ => {}
            }
            path.pop();
        }
    }
    color.insert(n, 2);
    None
}

/// Stepping order: the explicit one, or a topological order of the connections
/// (sources before their consumers), ties and cycles broken by declaration order.
pub(crate) fn stepping_order(
    file: &SystemFile,
    units: Units<'_>,
    connections: &[ConnectionDef],
) -> Result<Vec<usize>, OrderError> {
    let (instances, replays) = (units.instances, units.replays);
    let n_fmu = instances.len();
    let unit_names: Vec<&str> = instances
        .iter()
        .map(|i| i.name.as_str())
        .chain(replays.iter().map(|r| r.name.as_str()))
        .collect();
    let n = unit_names.len();
    if !file.experiment.order.is_empty() {
        let mut order = Vec::new();
        for name in &file.experiment.order {
            let k = unit_names
                .iter()
                .position(|u| u == name)
                .ok_or_else(|| OrderError::UnknownInstance { name: name.clone() })?;
            if order.contains(&k) {
                return Err(OrderError::Twice { name: name.clone() });
            }
            order.push(k);
        }
        if let Some(missing) = unit_names
            .iter()
            .enumerate()
            .find(|(k, _)| !order.contains(k))
        {
            return Err(OrderError::Missing {
                name: missing.1.to_string(),
            });
        }
        return Ok(order);
    }
    let mut deps: Vec<Vec<usize>> = vec![Vec::new(); n];
    for c in connections {
        let from = match c.from {
            Endpoint::Fmu { unit, .. } | Endpoint::Replay { unit, .. } => unit,
        };
        if from != c.to_unit && !deps[c.to_unit].contains(&from) {
            deps[c.to_unit].push(from);
        }
    }
    for (k, r) in replays.iter().enumerate() {
        if let Some((u, _)) = r.by.as_deref().and_then(split_name) {
            if let Some(src) = instances.iter().position(|i| i.name == u) {
                deps[n_fmu + k].push(src);
            }
        }
    }
    let mut done = vec![false; n];
    let mut order = Vec::with_capacity(n);
    while order.len() < n {
        let next = (0..n)
            .find(|&k| !done[k] && deps[k].iter().all(|&d| done[d]))
            .or_else(|| (0..n).find(|&k| !done[k]))
            .unwrap();
        done[next] = true;
        order.push(next);
    }
    Ok(order)
}
