"""[P] Table time: seconds per 1k points of MFPS, the feature cache and the network (full's), from the run's job
benchmark files, with the network's parameters per cluster and in total from the model definition."""

from refinenet.data.clouds import scored_points
from refinenet.data.io import read_cloud
from refinenet.network.model import architecture
from refinenet.network.summary import parameters
from refinenet.pipeline import stage
from refinenet.pipeline.layout import CLOUD, JOB_BENCHMARK, TIME_FILES
from refinenet.pipeline.timing import job_rows, time_table, write_time_table
from refinenet.pipeline.workflow import clouds

#: Quoted from the paper ([P] table:time), for the caption only.
PAPER = "2.2 s per 1k points, 10.4M parameters"


def arguments(parser):
    pass


def sizes(key, refined):
    """(key, points, featured points, refined points) of a test cloud, the network refining `refined` of them
    (`inference.points`)."""
    cloud = read_cloud(CLOUD.format(cloud=key))
    subsets = (None, scored_points(cloud), scored_points(cloud, refined))
    return key, *(len(cloud) if s is None else len(s) for s in subsets)


def main(params, args):
    keys = [c.key for c in clouds(params, "test")]
    jobs = job_rows([sizes(key, params.inference.points) for key in keys], JOB_BENCHMARK)
    per_cluster = parameters({"full": architecture(params.network, params.features, params.patches)})["full"]
    table = time_table(jobs, per_cluster, params.clustering.n_clusters)
    caption = (f"Time per 1k points (each job's wall time over the points it computed, process start included; CPU "
               f"MFPS and features, the network on inference.device = {params.inference.device}) and parameters "
               f"(Kc = {params.clustering.n_clusters} networks of the {params.network.preset} preset). Profile "
               f"{params.profile}; data: {params.data.source}, {len(keys)} test clouds of {params.data.n_points} "
               f"points. The paper reports {PAPER} (quoted; MFPS on a CPU, the network on a GPU).")
    write_time_table(jobs, table, caption, "table_time", TIME_FILES)


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
