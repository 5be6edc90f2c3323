"""Classical machine learning: dimensionality reduction, clustering, classifiers, metrics.

Every estimator keeps scikit-learn's contract (``fit`` returns self, learned attributes
end in ``_``, ``get_params``/``set_params``), so scikit-learn's ``clone``, ``Pipeline``
and ``cross_val_score`` accept them; scikit-learn is not needed to use them.
"""

from __future__ import annotations

from robopercept.learning._base import DataConversionWarning, clone
from robopercept.learning.dbscan import DBSCAN
from robopercept.learning.forest import RandomForestClassifier, RandomForestRegressor
from robopercept.learning.kmeans import KMeans, kmeans_plusplus
from robopercept.learning.lda import LDA
from robopercept.learning.meanshift import MeanShift, estimate_bandwidth
from robopercept.learning.metrics import (
    accuracy_score,
    adjusted_rand_score,
    auc,
    average_precision_score,
    classification_report,
    confusion_matrix,
    f1_score,
    precision_recall_curve,
    precision_score,
    recall_score,
    roc_auc_score,
    roc_curve,
)
from robopercept.learning.model_selection import (
    GridSearch,
    KFold,
    StratifiedKFold,
    cross_val_score,
    train_test_split,
)
from robopercept.learning.pca import PCA
from robopercept.learning.persist import (
    SavedModel,
    TablePrediction,
    load_model,
    predict_table,
    read_npz,
    save_model,
)
from robopercept.learning.report import (
    ClassCurves,
    ClassifierEvaluation,
    class_scores,
    confusion_table,
    evaluate_classifier,
    label_codes,
    read_features,
    read_table,
    standard_scaling,
    standardize,
)
from robopercept.learning.svm import SVC, LinearSVC
from robopercept.learning.tree import DecisionTreeClassifier, DecisionTreeRegressor

__all__ = [
    "DBSCAN",
    "LDA",
    "PCA",
    "SVC",
    "ClassCurves",
    "ClassifierEvaluation",
    "DataConversionWarning",
    "DecisionTreeClassifier",
    "DecisionTreeRegressor",
    "GridSearch",
    "KFold",
    "KMeans",
    "LinearSVC",
    "MeanShift",
    "RandomForestClassifier",
    "RandomForestRegressor",
    "SavedModel",
    "StratifiedKFold",
    "TablePrediction",
    "accuracy_score",
    "adjusted_rand_score",
    "auc",
    "average_precision_score",
    "class_scores",
    "classification_report",
    "clone",
    "confusion_matrix",
    "confusion_table",
    "cross_val_score",
    "estimate_bandwidth",
    "evaluate_classifier",
    "f1_score",
    "kmeans_plusplus",
    "label_codes",
    "load_model",
    "precision_recall_curve",
    "precision_score",
    "predict_table",
    "read_features",
    "read_npz",
    "read_table",
    "recall_score",
    "roc_auc_score",
    "roc_curve",
    "save_model",
    "standard_scaling",
    "standardize",
    "train_test_split",
]
