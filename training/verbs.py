"""The training package's ``cgh`` verbs, registered by the ``cgh.verbs`` entry point ``training``
(pyproject.toml; :mod:`cghair_format.cli.registry`). A new training verb is one line here."""

from cghair_format.cli.registry import Verb

VERBS: dict[str, Verb] = {
    "render-dataset": Verb("training.cli_dataset", "render a multi-view dataset of strands", output_folder=True),
    "train": Verb("training.cli_train", "fit the compact appearance model to a multi-view dataset",
                  make_parents=True),
    "eval": Verb("training.cli_eval", "PSNR, SSIM and LPIPS of a .cgh on a dataset's held-out views"),
    "ablation": Verb("training.ablation", "train the paper's appearance variants or codebook sweeps side by side"),
    "reconstruct": Verb("training.cli_reconstruct", "reconstruct strands from a multi-view dataset with hair masks"),
    "fit-strand-prior": Verb("training.cli_fit_prior", "fit a PCA basis of strand shapes for cgh reconstruct --prior"),
    "eval-strands": Verb("training.cli_eval_strands", "position, curvature, F1 of strands vs ground truth"),
}
